"""How do the cost weights shape an optimal reach?

Solves the reaching DOC from Berret's posture P2 (upper arm down, forearm forward) to a bar at 95 % of arm length
under three costs (joint acceleration alone, torque alone, torque change alone) and plots the joint angles and
the fingertip paths. Run: ``.venv/bin/python examples/quickstart.py --out /tmp/quickstart.png``.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from reachirl import FEATURES, ArmModel, ReachingTask, solve_doc
from reachirl.cli import OneLineParser
from reachirl.errors import InputError
from reachirl.validation import check_figure_file
from reachirl.virtual import posture_q


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="figure to write (PNG)")
    args = parser.parse_args(argv)
    try:  # before any work: a figure file matplotlib can write, in a folder that can be made
        check_figure_file(args.out, "--out").parent.mkdir(parents=True, exist_ok=True)
    except InputError as e:
        parser.error(str(e))

    arm = ArmModel.from_anthropometrics(height_m=1.76, mass_kg=70.0, sex="M")
    task = ReachingTask(arm, q0=posture_q("P2"), target_x=0.95 * arm.length, duration=0.75)
    fig, (ax_q, ax_p) = plt.subplots(1, 2, figsize=(10, 4))
    for name in ("joint_acceleration", "joint_torque", "torque_change"):
        weights = np.zeros((1, len(FEATURES)))
        weights[0, FEATURES.index(name)] = 1.0
        sol = solve_doc(task, weights)
        tip = arm.fk(sol.q)
        print(
            f"{name:20s} converged={sol.converged} iterations={sol.iterations} "
            f"cost={sol.cost:.4g} final fingertip=({tip[-1, 0]:.3f}, {tip[-1, 1]:.3f}) m"
        )
        line = ax_q.plot(sol.t, np.degrees(sol.q[:, 0]), label=f"{name} q1")[0]
        ax_q.plot(sol.t, np.degrees(sol.q[:, 1]), "--", color=line.get_color(), label=f"{name} q2")
        ax_p.plot(tip[:, 0], tip[:, 1], color=line.get_color(), label=name)
    ax_p.axvline(task.target_x, color="k", lw=1)
    ax_p.plot(0, 0, "ko")
    ax_q.set(xlabel="time (s)", ylabel="joint angle (deg)", title="Joint angles")
    ax_p.set(xlabel="x forward (m)", ylabel="y up (m)", title="Fingertip paths (bar in black)", aspect="equal")
    ax_q.legend(fontsize=7)
    ax_p.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    plt.close(fig)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
