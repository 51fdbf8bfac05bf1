"""An empty split or a number that cannot be computed is written as an explicit "no data" with its reason.

Result files never hold NaN (``io.to_jsonable`` turns a non-finite float into ``null``); every ``null`` mean
or summary gets a ``"no_data"`` entry beside it that says why, so that a reader never meets a bare ``null``
where a number is expected.
"""

from __future__ import annotations

import math

__all__ = ["annotate_no_data", "split_reasons"]

_SPLITS = ("train", "cv", "iscv")


def split_reasons(config=None) -> dict[str, str]:
    """Why each split of the protocol can be empty."""
    cv = getattr(config, "cv", "rest")
    side = getattr(config, "train_side", None)
    other = {"right": "left", "left": "right"}.get(side or "", "other")
    return {
        "train": "no training trials: the training subject has no trials of this posture (and side)",
        "cv": (
            f"no cross-validation trials: the training subject has no {other}-arm trials of this posture"
            if cv == "other-side"
            else "no cross-validation trials: the training set took every trial of the training subject "
            "for this posture (lower --n-train or record more trials)"
        ),
        "iscv": "no inter-subject trials: the data has no other subject with this posture",
        "other": "cannot be computed (no finite values)",
    }


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and not math.isfinite(v))


def annotate_no_data(obj, reasons: dict[str, str] | None = None, _split: str = "other"):
    """A copy of the JSON-able ``obj`` in which every dict with a missing (``None`` or non-finite) ``"mean"``
    has ``"no_data": reason``, and every ``"summary": None`` is ``{"n_trials": 0, "no_data": reason}``. The
    reason is that of the nearest enclosing split key (``train``, ``cv``, ``iscv``)."""
    reasons = reasons or split_reasons()
    if isinstance(obj, dict):
        n, failed = obj.get("n_trials"), obj.get("doc_failures")
        if isinstance(n, int) and not isinstance(n, bool) and n > 0:  # the set has trials: none gave a number
            why = (
                f"the DOC failed (did not converge) on all {n} trial(s) of this set; no RMSE"
                if isinstance(failed, int) and failed >= n
                else reasons["other"]
            )
            reasons = {**reasons, _split: why}
        out = {}
        for k, v in obj.items():
            split = k if k in _SPLITS else _split
            if k == "summary" and v is None:
                out[k] = {"n_trials": 0, "no_data": reasons.get(split, reasons["other"])}
            else:
                out[k] = annotate_no_data(v, reasons, split)
        if "mean" in out and _missing(out["mean"]) and "no_data" not in out:
            out["mean"] = None
            if "std" in out:
                out["std"] = None
            out["no_data"] = reasons.get(_split, reasons["other"])
        return out
    if isinstance(obj, list | tuple):
        return [annotate_no_data(v, reasons, _split) for v in obj]
    return obj


def csv_with_reasons(text: str, reasons: dict[str, str] | None = None) -> str:
    """``table.csv`` with a last column ``no_data``: for each row whose cells are empty because a split has no
    trials (``<split>_<sections>_n`` is 0), the reasons, ``"<split>: <reason>"`` joined by ``"; "``; empty
    otherwise. The numeric columns stay as they are (empty, never NaN)."""
    import csv
    import io

    reasons = reasons or split_reasons()
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        return text
    header = rows[0]
    n_cols = [(i, c.split("_", 1)[0]) for i, c in enumerate(header) if c.endswith("_n")]
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow([*header, "no_data"])
    for row in rows[1:]:
        empty = []
        for i, split in n_cols:
            if i < len(row) and row[i].strip() in ("0", "") and split not in empty:
                empty.append(split)
        w.writerow([*row, "; ".join(f"{s}: {reasons.get(s, reasons['other'])}" for s in empty)])
    return out.getvalue()
