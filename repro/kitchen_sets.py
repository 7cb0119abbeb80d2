"""One kitchen run's estimate sets (ALGORITHMS §12.2): how the bounded-error robot's set shrinks and grows.

The kitchen plan's first start, driven by the set estimator (``estimator="set"``) with a 60°
camera and every bearing error drawn uniformly within 0.25° (``noise_bound_deg``); the set is
recorded every 12 steps (``simulate.estimate_trace``) and drawn ten times enlarged about its
estimate, coloured by its error radius (``plot.plot_estimate_trace``).

Usage::

    .venv/bin/python repro/kitchen_sets.py plans/kitchen/plan.npz -o docs/figures/kitchen_sets.png
"""

from __future__ import annotations

import matplotlib.pyplot as plt
from common import arguments, load

from bearnav_cli import plot
from bearnav_cli.stages import simulate

FOV_DEG = 60.0
ETA_DEG = 0.25
EVERY = 12
SCALE = 10.0


def main() -> None:
    args = arguments(__doc__.splitlines()[0], [("plan", "plan.npz of the kitchen")])
    plan, _ = load(args.plan, "plan")
    params = simulate.Params(estimator="set", fov=FOV_DEG, noise_bound_deg=ETA_DEG, record_trajectories=False)
    trace = simulate.estimate_trace(plan, plan.map.starts[0], params, every=EVERY)
    plot.use_file_backend()
    xmin, ymin, xmax, ymax = plan.map.bounds
    fig, ax = plt.subplots(figsize=(9.0, 8.0 * (ymax - ymin) / (xmax - xmin) + 0.8))
    plot.plot_map(ax, plan.map)
    plot.plot_estimate_trace(ax, trace, scale=SCALE)
    ax.set_title(
        f"{plan.map.name}: one run's estimate sets ({FOV_DEG:g}° camera, bearing errors within "
        f"{ETA_DEG:g}°, {len(trace.error)} of them)",
        fontsize=10,
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.04), ncol=3, fontsize=7, frameon=False)
    fig.tight_layout()
    plot.save_figure(fig, str(args.out))


if __name__ == "__main__":
    main()
