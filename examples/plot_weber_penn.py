"""
Weber–Penn trees with knots
===========================

Three presets of Weber & Penn (1995) grown with the knots of paper 004
(:func:`mitsuba_veg.trees.weber_penn.generate`), drawn from the side with
:func:`mitsuba_veg.trees.figures.draw`.
"""
import matplotlib.pyplot as plt

from mitsuba_veg.trees import weber_penn as wp
from mitsuba_veg.trees.figures import draw

fig, axes = plt.subplots(1, 3, figsize=(10, 4))
for ax, preset in zip(axes, ("quaking_aspen", "ca_black_oak", "sassafras")):
    tree = wp.generate(preset, seed=1)
    m = tree.metrics()
    draw(ax, [tree], view="side", spheres=False, title=preset.replace("_", " "))
    print(f"{preset}: {m['height']:.1f} m tall, {m['leaves']:,d} leaves, "
          f"{tree.weber_penn.stats['knots']} knots")
fig.tight_layout()
