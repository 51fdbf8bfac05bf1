import numpy as np
import pinocchio as pin
import pytest

from reachirl import ArmModel
from reachirl.arm import DUMAS_2007


def random_states(rng, n=20):
    q = rng.uniform(-np.pi, np.pi, size=(n, 2))
    qd = rng.normal(0, 3, size=(n, 2))
    qdd = rng.normal(0, 20, size=(n, 2))
    return q, qd, qdd


def test_pinocchio_dynamics_match_closed_form(arm, rng):
    model = arm.pinocchio_model()
    data = model.createData()
    for q, qd, qdd in zip(*random_states(rng), strict=True):
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        np.testing.assert_allclose(M, arm.mass_matrix(q), atol=1e-9)
        np.testing.assert_allclose(pin.nonLinearEffects(model, data, q, qd), arm.bias(q, qd), atol=1e-9)
        np.testing.assert_allclose(pin.computeGeneralizedGravity(model, data, q), arm.gravity_torque(q), atol=1e-9)
        tau = pin.rnea(model, data, q, qd, qdd)
        np.testing.assert_allclose(tau, arm.inverse_dynamics(q, qd, qdd), atol=1e-9)
        np.testing.assert_allclose(pin.aba(model, data, q, qd, tau), qdd, atol=1e-9)
        np.testing.assert_allclose(arm.forward_dynamics(q, qd, tau), qdd, atol=1e-9)


def test_pinocchio_fingertip_frame_matches_fk(arm, rng):
    model = arm.pinocchio_model()
    data = model.createData()
    fid = model.getFrameId("fingertip")
    for q in rng.uniform(-np.pi, np.pi, size=(10, 2)):
        pin.framesForwardKinematics(model, data, q)
        np.testing.assert_allclose(data.oMf[fid].translation[:2], arm.fk(q), atol=1e-12)
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J[:2], arm.jacobian(q), atol=1e-12)


def test_fk_convention():
    arm = ArmModel(l1=0.3, l2=0.4, m1=2, m2=1.5, c1=0.15, c2=0.2, i1=0.01, i2=0.02)
    np.testing.assert_allclose(arm.fk([0.0, 0.0]), [0.7, 0.0], atol=1e-15)
    np.testing.assert_allclose(arm.fk([-np.pi / 2, 0.0]), [0.0, -0.7], atol=1e-15)  # hangs down
    np.testing.assert_allclose(arm.fk([0.0, np.pi / 2]), [0.3, 0.4], atol=1e-15)  # elbow flexed up
    np.testing.assert_allclose(arm.elbow([np.pi / 2, 1.0]), [0.0, 0.3], atol=1e-15)


def test_jacobian_matches_finite_differences(arm, rng):
    for q in rng.uniform(-np.pi, np.pi, size=(10, 2)):
        h = 1e-6
        fd = np.column_stack([(arm.fk(q + h * e) - arm.fk(q - h * e)) / (2 * h) for e in np.eye(2)])
        np.testing.assert_allclose(arm.jacobian(q), fd, atol=1e-8)


def test_fingertip_speed_is_the_rate_of_the_fingertip_position(arm, rng):
    q, qd, _ = random_states(rng)
    h = 1e-6  # the fingertip's displacement along q̇, by central differences of fk
    fd = np.linalg.norm((arm.fk(q + h * qd) - arm.fk(q - h * qd)) / (2 * h), axis=1)
    np.testing.assert_allclose(arm.fingertip_speed(q, qd), fd, rtol=1e-7)
    np.testing.assert_allclose(arm.fingertip_speed(q[0], np.zeros(2)), 0.0, atol=0.0)


def test_ik_round_trip_elbow_flexed(arm, rng):
    q = np.column_stack([rng.uniform(-2.0, 1.5, 50), rng.uniform(0.05, 2.6, 50)])
    np.testing.assert_allclose(arm.ik(arm.fk(q)), q, atol=1e-9)
    q_up = arm.ik(arm.fk(q), elbow_up=True)
    np.testing.assert_allclose(arm.fk(q_up), arm.fk(q), atol=1e-9)
    assert np.all(q_up[:, 1] <= 0)


def test_ik_out_of_reach_raises(arm):
    with pytest.raises(ValueError, match="out of reach"):
        arm.ik(np.array([arm.length * 1.1, 0.0]))


def test_energy_is_conserved_without_torque(arm):
    """Passive dynamics (τ = 0) conserve kinetic + potential energy: checks M, C and g together."""
    from scipy.integrate import solve_ivp

    def energy(x):
        q, qd = x[:2], x[2:]
        m1, m2, c1, c2, l1 = arm.m1, arm.m2, arm.c1, arm.c2, arm.l1
        pot = arm.gravity * (m1 * c1 * np.sin(q[0]) + m2 * (l1 * np.sin(q[0]) + c2 * np.sin(q[0] + q[1])))
        return 0.5 * qd @ arm.mass_matrix(q) @ qd + pot

    x0 = np.array([0.3, 0.8, 1.0, -2.0])
    sol = solve_ivp(
        lambda t, x: np.r_[x[2:], arm.forward_dynamics(x[:2], x[2:], np.zeros(2))], (0, 1.0), x0, rtol=1e-11, atol=1e-11
    )
    assert abs(energy(sol.y[:, -1]) - energy(x0)) < 1e-7


def test_from_anthropometrics_lumps_hand_by_parallel_axis():
    arm = ArmModel.from_anthropometrics(1.77, 80.0, "M", upper_arm_m=0.30, forearm_m=0.27, hand_m=0.19)
    mf, cf_pct, rf_pct, _ = DUMAS_2007["M"]["forearm"]
    mh, ch_pct, rh_pct, _ = DUMAS_2007["M"]["hand"]
    mf, mh = mf / 100 * 80, mh / 100 * 80
    cf, ch = cf_pct / 100 * 0.27, 0.27 + ch_pct / 100 * 0.19
    c2 = (mf * cf + mh * ch) / (mf + mh)
    i2 = mf * (rf_pct / 100 * 0.27) ** 2 + mf * (cf - c2) ** 2 + mh * (rh_pct / 100 * 0.19) ** 2 + mh * (ch - c2) ** 2
    assert arm.l1 == pytest.approx(0.30)
    assert arm.l2 == pytest.approx(0.46)
    assert arm.m1 == pytest.approx(0.024 * 80)
    assert arm.m2 == pytest.approx(mf + mh)
    assert arm.c1 == pytest.approx(0.452 * 0.30)
    assert arm.c2 == pytest.approx(c2)
    assert arm.i1 == pytest.approx(0.024 * 80 * (0.32 * 0.30) ** 2)
    assert arm.i2 == pytest.approx(i2)


def test_from_anthropometrics_defaults_scale_with_height():
    short = ArmModel.from_anthropometrics(1.60, 60, "F")
    tall = ArmModel.from_anthropometrics(1.80, 60, "F")
    assert tall.l1 / short.l1 == pytest.approx(1.80 / 1.60)
    assert 0.2 < short.l1 < 0.3 and 0.3 < short.l2 < 0.5


def test_sex_is_read_as_m_f_male_or_female():
    assert [ArmModel.from_anthropometrics(1.7, 70, s).m1 for s in ("M", "male", " MALE ")] == [
        ArmModel.from_anthropometrics(1.7, 70, "M").m1
    ] * 3
    assert ArmModel.from_anthropometrics(1.7, 70, "female").m1 == ArmModel.from_anthropometrics(1.7, 70, "F").m1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"height_m": 1.7, "mass_kg": 70, "sex": "X"}, "sex must be"),
        ({"height_m": 1.7, "mass_kg": 70, "sex": "Mouse"}, "sex must be"),  # not read as its first letter
        ({"height_m": 1.7, "mass_kg": 70, "sex": "fmale"}, "sex must be"),
        ({"height_m": 170, "mass_kg": 70, "sex": "M"}, "height_m 170.0 is not a stature"),
        ({"height_m": 1.7, "mass_kg": 0.07, "sex": "M"}, "mass_kg 0.07 is not a body mass"),
        ({"height_m": 1.7, "mass_kg": 70, "sex": "M", "forearm_m": 270}, "forearm_m 270.0 is not a segment length"),
    ],
)
def test_from_anthropometrics_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ArmModel.from_anthropometrics(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mass_kg": 72000}, r"^mass_kg 72000.0 is not a body mass in kg \(10-300\); in grams\?$"),
        ({"height_m": 172}, r"^height_m 172.0 is not a stature in metres \(0.5-2.6\); in centimetres\?$"),
        ({"height_m": 1720}, r"^height_m 1720.0 is not a stature in metres \(0.5-2.6\); in millimetres\?$"),
        ({"forearm_m": 27}, r"^forearm_m 27.0 is not a segment length in metres \(0.02-1.0\); in centimetres\?$"),
    ],
)
def test_from_anthropometrics_names_the_unit_a_value_was_likely_written_in(kwargs, match):
    """In the words of a subject-info file's refusal (tests/data/test_readers.py), without the subject and line."""
    with pytest.raises(ValueError, match=match):
        ArmModel.from_anthropometrics(**{"height_m": 1.7, "mass_kg": 70, "sex": "M", **kwargs})


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"height_m": None}, TypeError, r"height_m must be a number \(m\), got None"),
        ({"height_m": "tall"}, ValueError, r"height_m must be a number \(m\), got 'tall'"),
        ({"mass_kg": np.array([70.0, 80.0])}, TypeError, r"mass_kg must be a number \(kg\), got array"),
        ({"mass_kg": True}, TypeError, r"mass_kg must be a number \(kg\), got True"),
        ({"upper_arm_m": [0.3]}, TypeError, r"upper_arm_m must be a number \(m\), got \[0\.3\]"),
    ],
)
def test_from_anthropometrics_names_a_field_that_is_not_a_number(kwargs, error, match):
    """None, text, an array or a list name the field (float() and numpy's own words named none; a mass given
    as text failed multiplying a string)."""
    with pytest.raises(error, match=match):
        ArmModel.from_anthropometrics(**{"height_m": 1.7, "mass_kg": 70, "sex": "M", **kwargs})
    text = ArmModel.from_anthropometrics(height_m="1.7", mass_kg="70", sex="M")  # numbers as text, as float() reads
    assert text == ArmModel.from_anthropometrics(height_m=1.7, mass_kg=70.0, sex="M")


def test_arm_model_validates_fields():
    with pytest.raises(ValueError, match="l1 must be > 0"):
        ArmModel(l1=0, l2=0.4, m1=2, m2=1.5, c1=0.0, c2=0.2, i1=0.01, i2=0.02)
    with pytest.raises(ValueError, match="CoM must lie on its segment"):
        ArmModel(l1=0.3, l2=0.4, m1=2, m2=1.5, c1=0.5, c2=0.2, i1=0.01, i2=0.02)
    with pytest.raises(ValueError, match="must be finite"):
        ArmModel(l1=0.3, l2=float("nan"), m1=2, m2=1.5, c1=0.1, c2=0.2, i1=0.01, i2=0.02)


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("0.3", r"ArmModel\.l1 must be a number, got '0\.3' \(str\)"),  # was read as 0.3, silently
        (b"0.3", r"ArmModel\.l1 must be a number, got b'0\.3' \(bytes\)"),
        (True, r"ArmModel\.l1 must be a number, got True \(bool\)"),
        (np.complex128(0.3), r"ArmModel\.l1 must be a number, got .*\(complex128\)"),  # was 0.3 and a warning
        (None, r"ArmModel\.l1 must be a number, got None \(NoneType\)"),
    ],
)
def test_arm_model_refuses_what_is_not_a_number_by_its_type(value, match):
    with pytest.raises(ValueError, match=match):
        ArmModel(l1=value, l2=0.4, m1=2, m2=1.5, c1=0.1, c2=0.2, i1=0.01, i2=0.02)
    assert ArmModel(l1=np.float32(0.5), l2=0.4, m1=2, m2=1.5, c1=0.1, c2=0.2, i1=0.01, i2=0.02).l1 == 0.5  # numbers


def test_an_arm_in_millimetres_is_refused_where_it_is_made():
    """UE-ADL's subject table gives ADL001's right upper arm and forearm as 325 and 255 mm. An ArmModel given them
    as read (its CoMs likewise) was accepted, and refused only later, where a solve or a fit checked the arm (arm l1 =
    325 is outside the physical range); a trial carried it meanwhile. It is refused where it is made, naming the
    field and the unit; the same arm in metres, and any human arm, is kept."""
    metres = ArmModel.from_anthropometrics(1.702, 96.0, "F", upper_arm_m=0.325, forearm_m=0.255)
    mm = {**metres.to_dict(), **{k: getattr(metres, k) * 1000 for k in ("l1", "l2", "c1", "c2")}}
    with pytest.raises(
        ValueError,
        match=r"^ArmModel\.l1 must be in metres, got 325: longer than any arm segment "
        r"\(3 m; millimetres\?\)$",
    ):
        ArmModel(**mm)
    with pytest.raises(ValueError, match=r"^ArmModel\.l2 must be in metres, got 4\d\d\.\d+: longer"):
        ArmModel.from_dict({**metres.to_dict(), "l2": mm["l2"], "c2": mm["c2"]})
    assert ArmModel.from_dict(metres.to_dict()) == metres
    tall = ArmModel.from_anthropometrics(2.3, 150.0, "M", upper_arm_m=0.9, forearm_m=0.9, hand_m=0.5)
    assert tall.l2 == pytest.approx(1.4)


def test_arm_dict_round_trip(arm):
    assert ArmModel.from_dict(arm.to_dict()) == arm


def test_from_anthropometrics_matches_dumas_2007_by_hand():
    """A man of 80 kg with Dumas' mean lengths (upper arm 271, forearm 253, hand to fingertip 189 mm), computed
    by hand from Dumas et al. 2007's table: mass %, CoM % and r_zz % of (2.4, 45.2, 32), (1.7, 41.7, 27) and
    (0.6, 35.7, 24)."""
    arm = ArmModel.from_anthropometrics(1.77, 80.0, "M", upper_arm_m=0.271, forearm_m=0.253, hand_m=0.189)
    assert arm.m1 == pytest.approx(1.92) and arm.c1 == pytest.approx(0.122492)
    assert arm.i1 == pytest.approx(1.92 * 0.08672**2)
    # forearm 1.36 kg at 105.501 mm, hand 0.48 kg at 253 + 67.473 = 320.473 mm from the elbow
    assert arm.m2 == pytest.approx(1.84)
    c2 = (1.36 * 0.105501 + 0.48 * 0.320473) / 1.84
    assert arm.c2 == pytest.approx(c2)
    i2 = 1.36 * 0.06831**2 + 1.36 * (0.105501 - c2) ** 2 + 0.48 * 0.04536**2 + 0.48 * (0.320473 - c2) ** 2
    assert arm.i2 == pytest.approx(i2)
    assert arm.l2 == pytest.approx(0.442)


def test_dumas_hand_rows_to_the_fingertip_and_to_the_metacarpals_describe_the_same_hand():
    # Dumas 2007, men: metacarpal definition 80 mm, CoM 83.9 %, r_zz 56 %; fingertip definition 189 mm, 35.7 %, 24 %
    assert 0.839 * 0.080 == pytest.approx(0.357 * 0.189, abs=1e-3)  # CoM 67.1 vs 67.5 mm from the wrist
    assert 0.56 * 0.080 == pytest.approx(0.24 * 0.189, abs=1e-3)  # radius of gyration 44.8 vs 45.4 mm
    # so the default (fingertip) hand puts its CoM 67.5 mm from the wrist, not at 35.7 % of a shorter hand
    arm = ArmModel.from_anthropometrics(1.77, 80.0, "M", upper_arm_m=0.271, forearm_m=0.253, hand_m=0.189)
    x_hand = (arm.c2 * arm.m2 - 1.36 * 0.105501) / 0.48
    assert x_hand - 0.253 == pytest.approx(0.067473)


def test_default_forearm_is_dumas_mean_length():
    arm = ArmModel.from_anthropometrics(1.77, 80.0, "M", upper_arm_m=0.271, hand_m=0.189)
    assert arm.l2 == pytest.approx(0.253 + 0.189)
