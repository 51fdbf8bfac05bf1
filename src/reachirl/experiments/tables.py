"""The RMSE table in the seed's Table II layout, and the seed's own numbers beside it.

Layout: one block per posture and one for ALL postures; rows q1, q2, q; columns Training / CV / ISCV × the
section counts. Each cell is the mean ± SD (population SD, ``numpy.std``) of the per-trial RMSE in degrees.

**ALL postures.** The seed's ALL row is the mean over postures of the per-posture means, ± the SD of those
per-posture means (checked on its q1 column: training, 1 section, (11.32 + 15.10 + 11.78 + 3.97 + 7.05) / 5 =
9.84 ± 3.90, as printed). We do the same for ``ALL``, and also give ``ALL (trials)``: mean ± SD over every
trial of every posture pooled.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence

import numpy as np

from .names import natural_key, sections_text
from .protocol import SET_LABELS, SETS

__all__ = [
    "ALL",
    "ALL_TRIALS",
    "JOINTS",
    "SEED_TABLE",
    "build_table",
    "natural_key",
    "seed_markdown",
    "to_csv",
    "to_markdown",
]

JOINTS = ("q1", "q2", "q")
ALL = "ALL"
ALL_TRIALS = "ALL (trials)"
ALL_CONVENTION = (
    "ALL = mean over postures of the per-posture mean RMSE ± SD of those posture means "
    "(the seed's convention; with a single posture of trials in the set, its trials); "
    "ALL (trials) = mean ± SD over every trial of every posture pooled."
)

# Seed paper, Table II (Berret's human data, two subjects): posture -> joint -> 9 (mean, SD) cells, in the
# order Training 1/6/8, CV 1/6/8, ISCV 1/6/8 sections. Transcribed from the paper's LaTeX source
# ("2.78\pm1,78" read as 1.78).
_SEED_ROWS = {
    "P1": {
        "q1": [
            (11.32, 13.9),
            (5.87, 8.57),
            (2.54, 1.23),
            (8.71, 3.72),
            (4.15, 3.76),
            (2.98, 3.52),
            (7.99, 5.91),
            (7.87, 5.03),
            (8.94, 5.04),
        ],
        "q2": [
            (14.65, 12.4),
            (9.52, 9.48),
            (5.52, 4.98),
            (5.97, 2.73),
            (5.75, 5.19),
            (4.99, 5.29),
            (9.4, 2.29),
            (7.94, 4.24),
            (7.55, 2.94),
        ],
        "q": [
            (13.3, 13.0),
            (8.13, 8.84),
            (4.41, 3.48),
            (7.58, 2.98),
            (5.23, 4.28),
            (4.17, 4.44),
            (9.13, 3.6),
            (8.11, 4.28),
            (8.5, 3.63),
        ],
    },
    "P2": {
        "q1": [
            (15.1, 3.61),
            (4.91, 2.4),
            (4.46, 2.1),
            (7.32, 2.38),
            (3.54, 2.75),
            (4.19, 2.68),
            (9.3, 4.97),
            (3.58, 3.8),
            (3.31, 2.51),
        ],
        "q2": [
            (13.96, 2.56),
            (7.16, 1.74),
            (6.83, 2.46),
            (13.88, 6.96),
            (9.52, 6.59),
            (8.63, 2.58),
            (15.8, 4.08),
            (8.21, 3.67),
            (8.89, 4.14),
        ],
        "q": [
            (14.55, 3.08),
            (6.33, 1.47),
            (5.87, 2.01),
            (11.26, 4.84),
            (7.26, 4.93),
            (6.89, 2.34),
            (13.2, 3.66),
            (6.56, 3.31),
            (6.88, 3.07),
        ],
    },
    "P3": {
        "q1": [
            (11.78, 3.67),
            (4.53, 1.65),
            (7.06, 3.33),
            (14.31, 2.6),
            (8.93, 2.26),
            (9.85, 2.55),
            (13.05, 19.5),
            (8.63, 4.17),
            (8.84, 5.3),
        ],
        "q2": [
            (12.84, 3.27),
            (8.81, 2.12),
            (7.21, 3.78),
            (17.07, 3.42),
            (18.64, 6.68),
            (16.4, 7.4),
            (19.52, 9.57),
            (15.85, 8.34),
            (15.8, 10.1),
        ],
        "q": [
            (12.38, 3.28),
            (7.12, 1.24),
            (7.3, 3.22),
            (15.87, 2.32),
            (14.69, 4.75),
            (13.6, 5.27),
            (16.9, 8.06),
            (13.0, 6.09),
            (13.03, 7.76),
        ],
    },
    "P4": {
        "q1": [
            (3.97, 2.15),
            (3.69, 1.88),
            (3.47, 1.85),
            (2.78, 1.78),
            (2.95, 1.7),
            (2.57, 1.84),
            (4.67, 2.14),
            (4.13, 2.03),
            (4.08, 2.04),
        ],
        "q2": [
            (4.12, 1.94),
            (4.15, 1.61),
            (3.88, 1.75),
            (2.76, 1.56),
            (3.06, 1.9),
            (2.53, 1.48),
            (4.67, 2.14),
            (4.03, 2.84),
            (4.01, 2.8),
        ],
        "q": [
            (4.31, 1.43),
            (4.14, 1.15),
            (3.83, 1.47),
            (3.0, 1.12),
            (3.27, 1.28),
            (2.83, 1.14),
            (4.57, 2.02),
            (4.34, 1.97),
            (4.31, 1.96),
        ],
    },
    "P5": {
        "q1": [
            (7.05, 2.84),
            (8.17, 2.29),
            (7.83, 1.62),
            (16.86, 4.73),
            (9.83, 5.84),
            (8.26, 5.67),
            (13.8, 7.8),
            (7.86, 5.33),
            (9.63, 6.43),
        ],
        "q2": [
            (9.34, 4.17),
            (7.54, 3.71),
            (7.23, 3.16),
            (19.12, 4.95),
            (10.74, 7.38),
            (9.81, 5.15),
            (16.27, 5.91),
            (10.6, 4.66),
            (10.86, 4.57),
        ],
        "q": [
            (8.38, 3.32),
            (8.33, 1.4),
            (7.64, 2.18),
            (18.09, 4.58),
            (10.44, 6.42),
            (9.33, 4.96),
            (15.54, 5.82),
            (9.8, 4.11),
            (10.73, 4.62),
        ],
    },
    ALL: {
        "q1": [
            (9.84, 3.9),
            (5.43, 1.54),
            (5.07, 2.05),
            (10.0, 5.03),
            (5.88, 2.9),
            (5.57, 2.94),
            (9.76, 3.36),
            (6.41, 2.12),
            (6.96, 2.69),
        ],
        "q2": [
            (10.98, 3.89),
            (7.44, 1.85),
            (6.13, 1.29),
            (11.76, 6.35),
            (9.54, 5.3),
            (8.47, 4.73),
            (13.13, 5.35),
            (9.33, 3.88),
            (9.42, 3.89),
        ],
        "q": [
            (10.41, 3.81),
            (6.43, 1.42),
            (5.6, 1.57),
            (10.88, 5.51),
            (7.71, 3.86),
            (7.02, 3.77),
            (11.45, 4.27),
            (7.87, 2.8),
            (8.19, 2.93),
        ],
    },
}
SEED_SECTIONS = (1, 6, 8)
# posture -> set -> sections -> joint -> {"mean", "std"}
SEED_TABLE: dict = {
    p: {
        s: {
            n: {j: {"mean": rows[j][3 * i + k][0], "std": rows[j][3 * i + k][1]} for j in JOINTS}
            for k, n in enumerate(SEED_SECTIONS)
        }
        for i, s in enumerate(SETS)
    }
    for p, rows in _SEED_ROWS.items()
}
SEED_N_TRIALS = {"train": 10, "cv": 10, "iscv": 20}


def _stats(values: Sequence[float]) -> dict:
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return {"mean": None, "std": None, "n": 0}
    return {"mean": float(np.mean(v)), "std": float(np.std(v)), "n": int(v.size)}


def build_table(results: dict[str, dict], method: str, postures: Sequence[str], sections: Sequence[int]) -> dict:
    """``table[posture][set][sections][joint] = {"mean", "std", "n"}`` plus ``"doc_failures"`` per cell,
    with the ``ALL`` and ``ALL (trials)`` rows. ``results`` maps unit keys to unit results."""
    by = {(r["unit"]["method"], r["unit"]["posture"], r["unit"]["sections"]): r for r in results.values()}
    table: dict = {p: {s: {} for s in SETS} for p in [*postures, ALL, ALL_TRIALS]}
    for s in SETS:
        for n in sections:
            pooled = {j: [] for j in JOINTS}
            means = {j: [] for j in JOINTS}
            fails_all = 0
            for p in postures:
                r = by.get((method, p, n))
                trials = r["sets"][s]["trials"] if r else []
                cell = {}
                for j in JOINTS:  # a prediction whose DOC failed is counted, not averaged in
                    vals = [t["rmse_deg"][j] for t in trials if t.get("converged", True)]
                    cell[j] = _stats(vals)
                    pooled[j] += vals
                    if vals:
                        means[j].append(cell[j]["mean"])
                fails = sum(not t.get("converged", True) for t in trials)
                fails_all += fails
                cell["doc_failures"] = fails
                cell["flag"] = r.get("flag") if r else None
                table[p][s][n] = cell
            table[ALL_TRIALS][s][n] = {**{j: _stats(pooled[j]) for j in JOINTS}, "doc_failures": fails_all}
            if len(means["q"]) <= 1:  # an SD over one posture mean would read ± 0: give the trials' spread
                table[ALL][s][n] = {
                    k: dict(v) if isinstance(v, dict) else v for k, v in table[ALL_TRIALS][s][n].items()
                }
                continue
            table[ALL][s][n] = {**{j: _stats(means[j]) for j in JOINTS}, "doc_failures": fails_all}
            for j in JOINTS:
                table[ALL][s][n][j]["n"] = len(means[j])  # number of postures averaged
    return table


FLAG_MARKS = {"w0": "†", "one_step": "‡"}
FLAG_NOTE = (
    "† the fit never left its initial weights ω₀ (no step lowered the merit): those predictions are "
    "ω₀'s, not learned; ‡ the fit stopped after one step."
)


def _cell(c: dict | None, digits: int = 2, flag: str | None = None, fails: int = 0) -> str:
    failed = f" ({fails} DOC failed)" if fails else ""
    if not c or c.get("mean") is None:
        return "—" + failed
    return (
        f"{c['mean']:.{digits}f} ± {c['std']:.{digits}f}"
        + (f" {FLAG_MARKS[flag]}" if flag in FLAG_MARKS else "")
        + failed
    )


def table_rows(table: dict, postures: Sequence[str], sections: Sequence[int]) -> list[list[str]]:
    """``[posture, joint, cell, …]`` rows, cells formatted ``mean ± SD`` (the terminal and
    markdown layout)."""
    rows = []
    for p in [*postures, ALL, ALL_TRIALS]:
        for j in JOINTS:
            rows.append(
                [
                    p,
                    j,
                    *[
                        _cell(
                            table[p][s].get(n, {}).get(j),
                            flag=table[p][s].get(n, {}).get("flag"),
                            fails=table[p][s].get(n, {}).get("doc_failures", 0) if j == "q" else 0,
                        )
                        for s in SETS
                        for n in sections
                    ],
                ]
            )
    return rows


def to_markdown(
    table: dict, postures: Sequence[str], sections: Sequence[int], n_trials: dict[str, str], title: str = ""
) -> str:
    head = [
        "posture",
        "joint",
        *[f"{SET_LABELS[s]} ({n_trials.get(s, '?')}) · {sections_text(n)}" for s in SETS for n in sections],
    ]
    lines = [f"**{title}**", ""] if title else []
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + [":---:"] * (len(head) - 2)) + "|"]
    for row in table_rows(table, postures, sections):
        p, j = row[0], row[1]
        lines.append("| " + " | ".join([p if j == "q1" else "", f"**{j}**" if j == "q" else j, *row[2:]]) + " |")
    return "\n".join(lines) + "\n"


def to_csv(tables: dict[str, dict], postures: Sequence[str], sections: Sequence[int]) -> str:
    """Wide CSV in Table II's layout: ``method,posture,joint`` then ``<set>_<n>_mean``, ``<set>_<n>_std``,
    ``<set>_<n>_n`` for every set and section count (degrees, 4 decimals; empty when there are no trials), and
    ``<n>_flag`` per section count: ``w0`` (the fit never left its initial weights), ``one_step`` or empty."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = [f"{s}_{n}_{k}" for s in SETS for n in sections for k in ("mean", "std", "n")]
    cols += [f"{n}_flag" for n in sections]
    w.writerow(["method", "posture", "joint", *cols])
    for method, table in tables.items():
        for p in [*postures, ALL, ALL_TRIALS]:
            for j in JOINTS:
                vals = []
                for s in SETS:
                    for n in sections:
                        c = table[p][s].get(n, {}).get(j) or {"mean": None, "std": None, "n": 0}
                        vals += [
                            "" if c["mean"] is None else f"{c['mean']:.4f}",
                            "" if c["std"] is None else f"{c['std']:.4f}",
                            c["n"],
                        ]
                vals += [table[p]["train"].get(n, {}).get("flag") or "" for n in sections]
                w.writerow([method, p, j, *vals])
    return buf.getvalue()


def seed_markdown() -> str:
    """The seed's Table II (its results on Berret's human data) in the same layout."""
    n_trials = {s: str(v) for s, v in SEED_N_TRIALS.items()}
    postures = ["P1", "P2", "P3", "P4", "P5"]
    t = {p: SEED_TABLE[p] for p in [*postures, ALL]}
    head = [
        "posture",
        "joint",
        *[f"{SET_LABELS[s]} ({n_trials[s]}) · {sections_text(n)}" for s in SETS for n in SEED_SECTIONS],
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + [":---:"] * (len(head) - 2)) + "|"]
    for p in [*postures, ALL]:
        for j in JOINTS:
            cells = [_cell(t[p][s][n][j]) for s in SETS for n in SEED_SECTIONS]
            lines.append("| " + " | ".join([p if j == "q1" else "", f"**{j}**" if j == "q" else j, *cells]) + " |")
    return "\n".join(lines) + "\n"


def headline(table: dict, sections: Sequence[int]) -> list[dict]:
    """The ALL-postures q row, ours beside the seed's, per section count."""
    out = []
    for n in sections:
        row = {"sections": n}
        for s in SETS:
            row[s] = table[ALL][s].get(n, {}).get("q")
            row[f"seed_{s}"] = SEED_TABLE[ALL][s][n]["q"] if n in SEED_SECTIONS else None
        out.append(row)
    return out
