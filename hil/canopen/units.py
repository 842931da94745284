"""Unit scaling between physical values and the drive objects: the one place for it.

One name per conversion, ``<from>_to_<to>``: the public function (``rad_to_increments``, ...)
validates its arguments and quotes name and unit in the error. Where the simulated drives need a
conversion on their hot path, with values they already hold as finite floats, its unchecked kernel
carries the same name with ``_unchecked`` (``rad_to_increments_unchecked``, ...) and takes the
scale the drive keeps (increments per rad rather than counts per revolution); the public function
is built on it. The kernel *is* the formula; nobody writes it again.

============  ====================  ========================================
object        drive integer         physical value
============  ====================  ========================================
0x6064/607A   increments            motor angle [rad], N_rev / 2 pi inc/rad
0x6071/6077   per mille of T_rated  torque [N m]; ram force [N] via i_total
0x2100        0.001 mm (um)         LVDT stroke [mm]
0x2101        0.1 N (dN)            load-cell force [N]
============  ====================  ========================================
"""

from __future__ import annotations

import math

from canopen.objectdictionary import datatypes as dt

from hil.canopen.pdo import raw_encoder
from hil.canopen.validate import finite, positive

#: ``round(x)`` (ties to even) clipped to i32 / i16, ``x`` finite: the PDO codec's round-and-clip
#: (:func:`hil.canopen.pdo.encode_raw`) of an INTEGER32 / INTEGER16 object
_round_clip_i32 = raw_encoder(dt.INTEGER32)
_round_clip_i16 = raw_encoder(dt.INTEGER16)


# --------------------------------------------------------------------------- kernels (unchecked)


def rad_to_increments_unchecked(angle_rad: float, inc_per_rad: float) -> int:
    """Kernel of :func:`rad_to_increments`: ``round(phi k)`` clipped to i32."""
    return _round_clip_i32(angle_rad * inc_per_rad)


def increments_to_rad_unchecked(position_inc: float, inc_per_rad: float) -> float:
    """Kernel of :func:`increments_to_rad`: ``p / k`` [rad]."""
    return position_inc / inc_per_rad


def permille_to_force_N_unchecked(torque_permille: float, i_total_rad_per_mm: float,
                                  rated_torque_Nm: float) -> float:
    """Kernel of :func:`permille_to_force_N` [N]."""
    return torque_permille / 1000.0 * rated_torque_Nm * i_total_rad_per_mm * 1000.0


def torque_to_permille_unchecked(torque_Nm: float, rated_torque_Nm: float) -> int:
    """Kernel of :func:`force_to_permille` after the gear: motor torque [N m] in per mille of the rated
    torque (0x6077), rounded (ties to even), clipped to i16."""
    return _round_clip_i16(1000.0 * torque_Nm / rated_torque_Nm)


# --------------------------------------------------------------------------- validated


def increments_per_rad(counts_per_rev: int) -> float:
    """Position increments per radian of motor angle.

    Parameters
    ----------
    counts_per_rev : int
        Encoder increments per motor revolution (0x608F:01 / 0x608F:02), 4096
        for the 12-bit resolver.

    Returns
    -------
    float
        Increments per rad [1/rad].

    Notes
    -----
    .. math:: k = \\frac{N_{rev}}{2 \\pi}

    4096 counts/rev gives 651.898... inc/rad.
    """
    return positive("counts_per_rev", counts_per_rev, "increments/rev") / (2.0 * math.pi)


def rad_to_increments(angle_rad: float, counts_per_rev: int) -> int:
    """Motor angle [rad] to position increments (0x607A/0x6064), rounded, clipped to i32.

    Notes
    -----
    :math:`p = \\mathrm{round}(\\varphi \\, N_{rev} / 2\\pi)` [inc], clipped to
    -2**31 .. 2**31 - 1.
    """
    phi = finite("angle_rad", angle_rad, "rad")
    return rad_to_increments_unchecked(phi, increments_per_rad(counts_per_rev))


def increments_to_rad(position_inc: int, counts_per_rev: int) -> float:
    """Position increments to motor angle [rad].

    Notes
    -----
    :math:`\\varphi = 2\\pi \\, p / N_{rev}` [rad].
    """
    p = finite("position_inc", position_inc, "increments")
    return increments_to_rad_unchecked(p, increments_per_rad(counts_per_rev))


def force_to_permille(F_N: float, i_total_rad_per_mm: float, rated_torque_Nm: float) -> int:
    """Ram force [N] to a CST target torque (0x6071) in per mille of the rated torque.

    Parameters
    ----------
    F_N : float
        Ram force [N], positive in compression (the EMA pushes towards +s).
    i_total_rad_per_mm : float
        Total gear ratio motor angle / ram stroke [rad/mm], > 0.
    rated_torque_Nm : float
        Motor rated torque (0x6076 / 1000, the object is in mNm) [N m], > 0.

    Returns
    -------
    int
        Target torque [per mille of the rated torque], rounded to nearest
        (ties to even) and clipped to i16 (-32768..32767).

    Notes
    -----
    Lossless gear: the motor power equals the ram power,
    :math:`T \\omega = F v` with :math:`v = \\omega / (1000\\, i_{total})`, so

    .. math:: T = \\frac{F}{1000 \\, i_{total}}, \\qquad
              \\tau_{permille} = \\mathrm{round}\\left(1000 \\frac{T}{T_{rated}}\\right)

    with :math:`T` in N m, :math:`F` in N, :math:`i_{total}` in rad/mm. For
    i_total = 5.0265 rad/mm and T_rated = 1 N m, 1 per mille is 5.03 N.
    """
    F = finite("F_N", F_N, "N")
    i_total = positive("i_total_rad_per_mm", i_total_rad_per_mm, "rad/mm")
    t_rated = positive("rated_torque_Nm", rated_torque_Nm, "N m")
    return torque_to_permille_unchecked(F / (i_total * 1000.0), t_rated)


def permille_to_force_N(torque_permille: int, i_total_rad_per_mm: float, rated_torque_Nm: float) -> float:
    """Torque in per mille of the rated torque to the equivalent ram force [N].

    Notes
    -----
    Inverse of :func:`force_to_permille` (without rounding):
    :math:`F = 1000 \\, i_{total} \\, T_{rated} \\, \\tau_{permille} / 1000` [N].
    """
    tau = finite("torque_permille", torque_permille, "per mille")
    i_total = positive("i_total_rad_per_mm", i_total_rad_per_mm, "rad/mm")
    t_rated = positive("rated_torque_Nm", rated_torque_Nm, "N m")
    return permille_to_force_N_unchecked(tau, i_total, t_rated)


def mm_to_lvdt_um(stroke_mm: float) -> int:
    """LVDT stroke [mm] to the 0x2100 integer [0.001 mm], rounded, clipped to i32."""
    return _round_clip_i32(finite("stroke_mm", stroke_mm, "mm") * 1000.0)


def lvdt_um_to_mm(lvdt_um: int) -> float:
    """0x2100 LVDT stroke [0.001 mm] to mm."""
    return finite("lvdt_um", lvdt_um, "0.001 mm") / 1000.0


def newton_to_force_dN(F_N: float) -> int:
    """Load-cell force [N] to the 0x2101 integer [0.1 N], rounded, clipped to i32."""
    return _round_clip_i32(finite("F_N", F_N, "N") * 10.0)


def force_dN_to_newton(force_dN: int) -> float:
    """0x2101 load-cell force [0.1 N] to N."""
    return finite("force_dN", force_dN, "0.1 N") / 10.0
