#!/usr/bin/env bash
# The light, world, sensor and render tests on the GPU variant (cuda_ad_spectral): what
# `make test-gpu` runs on a machine with a CUDA GPU (CI runs the whole suite on the CPU).
#
#   PY=.venv/bin/python bash scripts/test-gpu.sh [pytest arguments]
#
# Fails at once when CUDA does not work rather than testing the CPU variant again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
export MITSUBA_VEG_VARIANT=cuda_ad_spectral
"$PY" -c "import mitsuba_veg as mv, sys; v = mv.variant(); print('[test-gpu] variant', v); sys.exit(v != 'cuda_ad_spectral')"
exec "$PY" -m pytest -m "not slow" -q \
    tests/test_determinism.py tests/test_photon_plugin.py tests/test_photon_irradiance.py \
    tests/test_photon_record.py tests/test_photon_modes.py tests/test_photon_bsdf_override.py \
    tests/test_photon_scenes.py tests/test_photon_weights.py tests/test_light_system.py \
    tests/test_sensors.py tests/test_daylight.py tests/test_moss_run.py tests/test_world.py \
    tests/test_render.py tests/test_render_parts.py tests/test_render_cli.py \
    tests/test_tune_photon.py "$@"
