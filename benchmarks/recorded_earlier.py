"""Figures measured on machines the docs build does not have (an NVIDIA H200) or in runs of an hour
and more, carried as ``benchmarks/results/*.json`` with the machine and date they were measured on
(``source = "recorded earlier"``). Rerun the named benchmark there to replace a file with a
measurement; ``python benchmarks/recorded_earlier.py`` writes these files again."""
import sys
sys.path.insert(0, __import__("os").path.dirname(__file__))
from _record import write_recorded

H200 = {"cpu": "not recorded", "cores": None, "gpu": "NVIDIA H200", "system": "Linux"}
CPU2 = {"cpu": "AMD EPYC", "cores": 2, "gpu": None, "system": "Linux"}
SRC = "figures stated in the README and the world docs"

write_recorded("world_year_gpu", "python benchmarks/world_year.py", [
    ("run_s", 13.0, "s", "365 days of the world, wall time"),
    ("light_ms", 7.0, "ms", "light per day (mean)"),
    ("leaves_ms", 1.0, "ms", "leaves per day (mean)"),
    ("soil_ms", 1.0, "ms", "soil per day (mean)"),
    ("moss_ms", 5.0, "ms", "moss per day (mean)"),
], H200, "cuda_ad_spectral", "2026-11-27", notes="the courtyard plus a sassafras and a second "
   "aspen (117,636 leaves), 1M photons a day, 365 days from 1 March; " + SRC)

write_recorded("world_day_gpu", "python benchmarks/world_day.py --days 10", [
    ("day_ms", 23.7, "ms", "steady world day (median)"),
    ("light_ms", 7.9, "ms", "of which light"),
    ("moss_ms", 11.3, "ms", "of which moss"),
    ("soil_ms", 0.5, "ms", "of which soil"),
    ("leaves_ms", 0.3, "ms", "of which leaves"),
    ("record_ms", 3.4, "ms", "of which record"),
    ("day_no_compile_ms", 16.9, "ms", "day that compiled nothing (median)"),
    ("bare_pass_ms", 13.5, "ms", "bare photon pass, same scene, tables and photon split"),
], H200, "cuda_ad_spectral", "2026-11-27", notes="the courtyard world of world_year.py, 10 days "
   "from 1 July after two warm-up days; " + SRC)

write_recorded("photon_throughput_garden_gpu", "python benchmarks/photon_throughput.py --scene garden --photons 1000000 16000000", [
    ("ratio_preliminary_1M", 0.11, "ratio", "pass ray casts/s ÷ `ray_intersect_preliminary` rays/s, 1M photons"),
    ("ratio_preliminary_16M", 0.18, "ratio", "pass ray casts/s ÷ `ray_intersect_preliminary` rays/s, 16M photons"),
], H200, "cuda_ad_spectral", "2026-11-27", notes="80k-triangle garden, sun + sky; " + SRC)

write_recorded("forest_hectare_gpu", "python benchmarks/forest_hectare.py --days 3653", [
    ("setup_s", 28.2, "s", "set-up"),
    ("run_s", 310.0, "s", "3,653 days after the set-up"),
    ("ten_years_s", 338.0, "s", "ten years with the set-up (target 900 s)"),
    ("day_s", 0.019, "s", "per day besides the year ends"),
    ("year_ends_s", 242.0, "s", "the ten year ends in all"),
    ("gpu_memory_gb", 20.6, "GB", "GPU memory (nvidia-smi's peak)"),
    ("host_memory_gb", 13.75, "GB", "host memory, resident at most"),
], H200, "cuda_ad_spectral", "2026-11-27", notes="300 Weber-Penn aspens on 1 ha (6,728,166 "
   "leaves), 1M photons a pass, a pass every fourth day, no checkpoints; the trees aged on one "
   "host thread then; figures stated in the forest docs")

write_recorded("forest_hectare_cpu", "python benchmarks/forest_hectare.py", [
    ("setup_s", 68.0, "s", "set-up"),
    ("run_s", 784.0, "s", "366 days after the set-up"),
    ("day_s", 2.14, "s", "per day (mean)"),
    ("bytes_per_leaf", 1918.0, "B", "memory per leaf after the first day (its share of wood, floor and pass)"),
    ("regrowth_share", 0.040, "fraction", "the year's end (regrowth) against 365 ordinary days"),
    ("peak_memory_gb", 16.3, "GB", "peak memory (of the machine's 24 GB)"),
], CPU2, "llvm_ad_spectral", "2026-11-28", notes="300 Weber-Penn aspens on 1 ha (6,728,166 "
   "leaves), 1M photons a pass, a pass every fourth day; nothing else running; figures stated "
   "in the forest docs")

write_recorded("forest_stand", "python benchmarks/forest_stand.py --years 10", [
    ("run_s", 1711.0, "s", "10 years (3,653 days)"),
    ("day_s", 0.468, "s", "per day (mean)"),
    ("ten_years_over_target", 0.95, "ratio", "scaled to 10 years ÷ the 1,800 s target"),
    ("peak_memory_gb", 6.4, "GB", "peak memory"),
], CPU2, "llvm_ad_spectral", "2026-11-27", notes="scenes/forest_stand (36 trees, 1M photons a "
   "pass, a pass every fourth day), ten years; nothing else running; figures stated in "
   "the forest docs")

write_recorded("stand_instancing", "python benchmarks/stand_instancing.py", [
    ("n500_leaves", 11_200_000, "", "500 aspens: leaves"),
    ("bytes_per_leaf_plain", 1818.0, "B", "per leaf with plain meshes (leaves recorded)"),
    ("bytes_per_leaf_instanced", 831.0, "B", "per leaf with instances (leaves recorded, at most)"),
    ("n500_plain_load_s", 349.9, "s", "500 aspens, plain meshes: scene load"),
    ("n500_instanced_load_s", 1.09, "s", "500 aspens, instanced: scene load"),
    ("n500_plain_rss_mb", 7405.0, "MB", "500 aspens, plain meshes: memory after load"),
    ("n500_instanced_rss_mb", 43.0, "MB", "500 aspens, instanced: memory after load"),
], CPU2, "llvm_ad_spectral", "2026-11-27", notes="stands of quaking aspens at 400/ha, 3 variants; "
   "a machine shared with other jobs (load average 4-7); figures stated in the forest docs")
