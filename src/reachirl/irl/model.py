"""The learned-model file (``MODEL.json``) that ``fit`` writes and ``evaluate``/``simulate`` read."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..features import FEATURES, N_FEATURES
from ..io import atomic_write_json, read_json

__all__ = ["MODEL_FORMAT", "LearnedModel", "load_model", "save_model"]

MODEL_FORMAT = "reachirl-model/1"


@dataclass(frozen=True)
class LearnedModel:
    """Weights ``(n_windows, 7)`` (columns in FEATURES order), the DOC discretisation they were learned on, and
    free-form provenance (method, hyperparameters, history, training trials)."""

    weights: np.ndarray
    n_nodes: int = 100
    method: str = "moirl"
    info: dict = field(default_factory=dict)
    uncertainty: dict | None = None  # weight samples the training data cannot tell apart (reachirl.irl.uncertainty)

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=float)
        if w.ndim != 2 or w.shape[1] != N_FEATURES:
            raise ValueError(f"weights must have shape (n_windows, {N_FEATURES}), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weights must be finite and >= 0")
        object.__setattr__(self, "weights", w)

    @property
    def n_windows(self) -> int:
        return self.weights.shape[0]


def save_model(path: str | Path, model: LearnedModel) -> Path:
    atomic_write_json(
        path,
        {
            "format": MODEL_FORMAT,
            "method": model.method,
            "n_windows": model.n_windows,
            "n_nodes": model.n_nodes,
            "features": list(FEATURES),
            "weights": model.weights,
            "info": model.info,
            **({} if model.uncertainty is None else {"uncertainty": model.uncertainty}),
        },
    )
    return Path(path)


def load_model(path: str | Path) -> LearnedModel:
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") != MODEL_FORMAT:
        raise InputError(f"not a reachirl model file (expected format {MODEL_FORMAT!r})", path)
    if "features" not in d or "weights" not in d:
        raise InputError("model lacks its 'features' or 'weights' entry", path)
    if list(d["features"]) != list(FEATURES):
        raise InputError(f"feature list {d.get('features')} differs from {list(FEATURES)}", path)
    try:
        return LearnedModel(
            weights=np.asarray(d["weights"], dtype=float),
            n_nodes=int(d.get("n_nodes", 100)),
            method=str(d.get("method", "moirl")),
            info=dict(d.get("info", {})),
            uncertainty=d.get("uncertainty") if isinstance(d.get("uncertainty"), dict) else None,
        )
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"malformed model ({e})", path) from None
