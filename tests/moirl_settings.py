"""Settings of the MO-IRL tests: the estimator's options moved into ``experimental``, and the iteration on whole
rollouts with the full-state merit."""


def moirl_params(params: dict) -> dict:
    """``params`` with the fields of :class:`reachirl.irl.options.Options` moved into ``experimental``."""
    from reachirl.irl.options import FIELDS

    exp = {k: v for k, v in params.items() if k in FIELDS}
    rest = {k: v for k, v in params.items() if k not in FIELDS}
    if exp:
        rest["experimental"] = {**rest.get("experimental", {}), **exp}
    return rest


def whole_rollout_moirl(cls):
    """``cls`` with whole rollouts and the full-state merit unless a test says otherwise: the setting of the
    tests of MO-IRL's iteration (the line search, the fallback, the scale-free step) on DOC-made reaches."""

    def make(*args, **kwargs):
        kwargs = moirl_params(kwargs)
        kwargs["experimental"] = {"observe": False, "merit": "state", **(kwargs.get("experimental") or {})}
        return cls(*args, **kwargs)

    return make
