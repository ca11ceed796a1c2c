"""The main job of ``make demo``: the benchmark's quick scenario (kinematics demo until it lands)."""

from __future__ import annotations

import numpy as np

from hexapod import deltalab, forward_kinematics, inverse_kinematics, sample_poses


def main() -> int:
    """Print a short, readable kinematics demo of the reference robot."""
    g = deltalab()
    print(f"Reference robot '{g.name}': stroke {g.q_min * 1e3:.0f}-{g.q_max * 1e3:.0f} mm, "
          f"leg radius {g.leg_radius * 1e3:.0f} mm, home height {g.home_height * 1e3:.1f} mm")
    R, t = sample_poses(g, 5, rng=1)
    q = inverse_kinematics(g, R, t)
    print(f"{'pose':>4} {'x mm':>8} {'y mm':>8} {'z mm':>8}   leg lengths mm"
          f"{'':>30} FK error mm")
    for k in range(len(q)):
        sol = forward_kinematics(g, q[k])
        err = np.linalg.norm(sol.translation - t[k]) * 1e3
        legs = " ".join(f"{x * 1e3:6.1f}" for x in q[k])
        print(f"{k:>4} {t[k, 0] * 1e3:8.1f} {t[k, 1] * 1e3:8.1f} {t[k, 2] * 1e3:8.1f}   {legs}"
              f"   {err:.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
