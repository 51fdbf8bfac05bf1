"""The method a run used, in words, from the options each unit recorded: MO-IRL as the seed paper writes it, or
the paper's iteration with each departure from it that was in force; and the merit's units, which the
convergence figure names."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from ..irl.options import Options, departures, resolve_options

__all__ = ["MERIT_LABELS", "convergence_text", "merit_label", "method_lines", "unit_method"]

#: the y-axis of a merit plot, per ``merit`` option
MERIT_LABELS = {
    "state": "merit m(x) = mean ‖x* − x‖²\n(x = q in rad, q̇ in rad/s)",
    "normalised": "normalised merit m(x) (unitless)\n(each of q, q̇ over the demonstrations' spread)",
}


def merit_label(merit: str | None) -> str:
    """The axis label of the merit ``merit`` (``"state"``, ``"normalised"``; None: not recorded)."""
    return MERIT_LABELS.get(merit, "merit m(x)\n(its form was not recorded)")


def unit_method(method: str, estimator_options, tol: float | None, tasks: int | None = None) -> dict | None:
    """What an MO-IRL unit (or one built on MO-IRL, such as MaxEnt) ran, from its recorded ``estimator_options``
    (``seed_form``, ``rollout``, ``experimental``; pairs or a mapping) and ``tol`` (None: the method's default):
    ``{"seed_form", "options" (every option in force), "rollout", "tol", "departures" (each departure from the
    paper, in words)}``. None for a method that is not MO-IRL (its options are its own).

    ``tasks``: how many (subject, posture) tasks the unit learned from, when known; from one task, one rollout
    per task is the paper's one rollout from the demonstrations' mean, not a departure."""
    from ..irl.methods import METHODS
    from ..irl.moirl import DEFAULT_TOL, MOIRL

    cls = METHODS.get(method)
    if cls is None or not issubclass(cls, MOIRL):
        return None
    from .protocol import estimator_kwargs

    opts = estimator_kwargs(estimator_options or ())
    experimental = opts.get("experimental") or {}
    seed_form = bool(opts.get("seed_form", False))
    options: Options = resolve_options(seed_form, experimental, cls._option_defaults)
    rollout = str(opts.get("rollout", "mean" if seed_form else "per_task"))
    tol = (0.0 if seed_form else DEFAULT_TOL) if tol is None else float(tol)
    as_paper = "mean" if rollout == "per_task" and tasks == 1 else rollout
    return {
        "seed_form": seed_form,
        "options": options.to_dict(),
        "rollout": rollout,
        "tol": tol,
        "departures": departures(options, as_paper, tol, cls._option_defaults),
        "defining": dict(cls._option_defaults),
    }


def _iteration(o: Mapping) -> str:
    return (
        f"β = {o['beta']:g}, ω₀ = {o['w0']:g}, α = {o['alpha0']:g} shrinking by {o['shrink']:g}, "
        f"at most {o['max_tries']} tries"
    )


def method_lines(units: Sequence[Mapping]) -> list[str]:
    """Markdown list items that state the method of each method run, from the units' records (``results.json``'s
    ``unit`` entries: ``method``, ``posture``, ``estimator_options``, ``tol``): for MO-IRL either the paper's
    method as written, or the paper's iteration and each departure from it that was used; other methods are
    named as baselines with their own options. A unit of one posture learned from one subject's trials of it:
    one task."""
    lines: list[str] = []
    seen: dict[str, list] = {}
    for u in units:
        seen.setdefault(u["method"], []).append(u)
    for method, group in seen.items():
        described = [
            unit_method(
                method, u.get("estimator_options"), u.get("tol"), tasks=1 if isinstance(u.get("posture"), str) else None
            )
            for u in group
        ]
        if described[0] is None:
            lines.append(f"- **{method}:** a baseline, with its own options (not MO-IRL's).")
            continue
        kinds = {(tuple(d["departures"]), d["seed_form"]) for d in described}
        if len(kinds) > 1:
            lines.append(f"- **{method}:** its units ran with different options; each unit's are in results.json.")
            continue
        d = described[0]
        o = d["options"]
        own = ", ".join(f"{k} = {v!r}" for k, v in d["defining"].items())
        if not d["departures"]:
            lines.append(
                f"- **{method}:** the seed paper's MO-IRL as written"
                f"{' (seed form)' if d['seed_form'] else ''}"
                + (f" but for {method}'s own {own}" if own else "")
                + f": the raw subproblem with {_iteration(o)}, any fall "
                "of the full-state merit accepted, no other step, the DOC at rest at both ends over each "
                "trial's duration." + ("" if own else " This is the paper's method.")
            )
            continue
        lines.append(
            f"- **{method}:** the seed paper's MO-IRL iteration ({_iteration(o)})"
            + (f", with {method}'s own {own}," if own else "")
            + f" with {len(d['departures'])} departure(s) from the paper:"
        )
        lines += [f"  - {text}" for text in d["departures"]]
    return lines


def convergence_text(options: Mapping | None) -> dict[str, str]:
    """The convergence figure's words for a fit of these options (a mapping with ``merit`` and ``observe``; None
    or missing keys: not recorded): ``{"merit_label"`` (y axis), ``"start"`` (what iteration 0's weights are),
    ``"caption"}``. An observed fit's history is its second stage, which starts where the first (the same
    options, rollouts not observed) ended, not at ω₀."""
    options = options or {}
    merit, observe = options.get("merit"), options.get("observe")
    units = {
        "state": " The merit is the full-state error, q in rad and q̇ in rad/s.",
        "normalised": " The merit is the normalised one (each of q and q̇ divided by the demonstrations' "
        "spread): it has no units.",
    }.get(merit, "")
    if observe:
        start = "where the first stage ended"
        caption = (
            "Merit of every fit at each accepted iteration of its observed stage (rollouts seen as the "
            "demonstrations were recorded). Iteration 0 is where the fit's first stage (the same options, "
            "rollouts not observed) ended, not the initial weights ω₀; trials not cut at a speed "
            "threshold have that stage only, from ω₀."
        )
    elif observe is None:
        start = "the fit's first weights"
        caption = "Merit of every fit at each accepted iteration (iteration 0: the weights the fit started from)."
    else:
        start = "the initial weights ω₀"
        caption = "Merit of every fit at each accepted iteration (iteration 0: the initial weights ω₀)."
    return {"merit_label": merit_label(merit), "start": start, "caption": caption + units}
