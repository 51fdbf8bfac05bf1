"""The arm's equations on CasADi symbols, for the DOC backends that build CasADi expressions
(:mod:`reachirl.doc.casadi`'s NLP, :mod:`reachirl.doc.newton`'s stage derivatives): the same closed forms as
:class:`reachirl.arm.ArmModel`. ``arm`` is the list of :data:`ARM_FIELDS` as symbols."""

from __future__ import annotations

import casadi as ca

__all__ = ["ARM_FIELDS", "fingertip", "fingertip_jacobian", "inverse_dynamics", "mass_matrix"]

ARM_FIELDS = ("l1", "l2", "m1", "m2", "c1", "c2", "i1", "i2", "gravity")


def inverse_dynamics(arm, q, qd, qdd):
    """Closed-form ``τ = M q̈ + C q̇ + g`` (the same equations as ArmModel)."""
    l1, _l2, m1, m2, c1, c2, i1, i2, g = arm
    cq2, sq2 = ca.cos(q[1]), ca.sin(q[1])
    a = i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2)
    b = m2 * l1 * c2
    d = i2 + m2 * c2**2
    h = b * sq2
    g2 = g * m2 * c2 * ca.cos(q[0] + q[1])
    g1 = g * (m1 * c1 + m2 * l1) * ca.cos(q[0]) + g2
    tau1 = (a + 2 * b * cq2) * qdd[0] + (d + b * cq2) * qdd[1] - h * (2 * qd[0] * qd[1] + qd[1] ** 2) + g1
    tau2 = (d + b * cq2) * qdd[0] + d * qdd[1] + h * qd[0] ** 2 + g2
    return ca.vertcat(tau1, tau2)


def mass_matrix(arm, q):
    """``M(q)``."""
    l1, _l2, m1, m2, c1, c2, i1, i2, _g = arm
    cq2 = ca.cos(q[1])
    a = i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2)
    b = m2 * l1 * c2
    d = i2 + m2 * c2**2
    return ca.vertcat(ca.horzcat(a + 2 * b * cq2, d + b * cq2), ca.horzcat(d + b * cq2, d))


def fingertip(arm, q):
    """The fingertip's position ``(P_x, P_y)``."""
    l1, l2 = arm[0], arm[1]
    return ca.vertcat(l1 * ca.cos(q[0]) + l2 * ca.cos(q[0] + q[1]), l1 * ca.sin(q[0]) + l2 * ca.sin(q[0] + q[1]))


def fingertip_jacobian(arm, q):
    """``∂P/∂q (2, 2)``."""
    l1, l2 = arm[0], arm[1]
    q1, q12 = q[0], q[0] + q[1]
    return ca.vertcat(
        ca.horzcat(-l1 * ca.sin(q1) - l2 * ca.sin(q12), -l2 * ca.sin(q12)),
        ca.horzcat(l1 * ca.cos(q1) + l2 * ca.cos(q12), l2 * ca.cos(q12)),
    )
