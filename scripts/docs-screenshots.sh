#!/usr/bin/env bash
# Screenshots of built documentation pages in a headless browser (Debian's chromium), to look at
# after `make docs-html`:
#   bash scripts/docs-screenshots.sh [OUT_DIR] [PAGE ...]
# PAGE is a path under docs/_build/html (default: a few pages of each kind); the PNGs go to
# OUT_DIR (default out/docs-screenshots), one per page, 1280 px wide.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/docs-screenshots}
shift || true
pages=("$@")
if [ ${#pages[@]} -eq 0 ]; then
    pages=(index.html render.html tutorials/first_run.html explanation/performance.html
           reference/cli.html reference/plugins/index.html hemiphoto.html)
fi
browser=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$browser" ]; then
    echo "docs-screenshots: no chromium (apt-get install -y chromium)" >&2
    exit 1
fi
html=$PWD/docs/_build/html
if [ ! -f "$html/index.html" ]; then
    echo "docs-screenshots: no built site in $html (run: make docs-html)" >&2
    exit 1
fi
mkdir -p "$out"
for page in "${pages[@]}"; do
    if [ ! -f "$html/$page" ]; then
        echo "docs-screenshots: no page $page in $html" >&2
        exit 1
    fi
    png="$out/$(echo "$page" | tr '/' '_' | sed 's/\.html$//').png"
    "$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --window-size=1280,2000 --screenshot="$png" "file://$html/$page" >/dev/null 2>&1
    echo "$png"
done
