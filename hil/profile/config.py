"""Validated, frozen configuration of the actuation and of the check.

Each field carries its unit in its name and, in its metadata, the range a
profile may give it. ``hard_max`` bounds are hard caps that no profile can
raise (they are the envelope the check must never leave); see
:mod:`hil.profile.load` for loading from TOML.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hil.canopen.signalmap import SignalMap
from hil.profile.floors import DUAL_FLOORS


def _rng(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
         hard_max: float | None = None, doc: str = "") -> dict:
    """Field metadata: allowed range and hard cap."""
    return {"lo": lo, "hi": hi, "lo_open": lo_open, "hard_max": hard_max, "doc": doc}


# ---------------------------------------------------------------- actuation


@dataclass(frozen=True)
class Mechanics:
    i_total_rad_per_mm: float = field(metadata=_rng(0.0, 1e4, lo_open=True))
    stroke_limit_mm: float = field(metadata=_rng(0.0, 200.0, lo_open=True))
    limit_load_N: float = field(metadata=_rng(0.0, 1e6, lo_open=True))
    backlash_spec_int_mm: float = field(metadata=_rng(0.0, 5.0, lo_open=True))
    backlash_spec_ext_mm: float = field(metadata=_rng(0.0, 5.0, lo_open=True))
    #: the stiffness [N/mm] the internal chain (motor to ram, int1/int2) and the external one (ext) can have:
    #: a channel measured outside is not this actuation's (hil.analysis.plausible); 0 (the default): derived,
    #: limit_load_N / stroke_limit_mm .. force-fight level / sensors.lvdt_noise_pp_mm
    stiffness_int_min_N_per_mm: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    stiffness_int_max_N_per_mm: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    stiffness_ext_min_N_per_mm: float = field(default=0.0, metadata=_rng(0.0, 1e9))
    stiffness_ext_max_N_per_mm: float = field(default=0.0, metadata=_rng(0.0, 1e9))


@dataclass(frozen=True)
class Sensors:
    lvdt_full_scale_mm: float = field(metadata=_rng(0.0, 500.0, lo_open=True))
    lvdt_noise_pp_mm: float = field(metadata=_rng(0.0, 1.0, lo_open=True))
    loadcell_noise_std_N: float = field(metadata=_rng(0.0, 1e4, lo_open=True))


@dataclass(frozen=True)
class Timing:
    sync_period_s: float = field(metadata=_rng(1e-4, 0.1))


@dataclass(frozen=True)
class Canopen:
    """The CAN bus and the two drives as the master expects them."""

    node_id_ema1: int = field(metadata=_rng(1, 127))
    node_id_ema2: int = field(metadata=_rng(1, 127))
    bitrate_bps: int = field(metadata=_rng(10_000, 1_000_000))
    heartbeat_period_s: float = field(metadata=_rng(0.01, 10.0))  #: producer heartbeat set in the drives (0x1017)
    heartbeat_timeout_factor: float = field(metadata=_rng(1.1, 10.0))  #: consumer timeout = factor * period
    boot_timeout_s: float = field(metadata=_rng(0.1, 60.0))  #: wait for boot-up after NMT reset
    sdo_timeout_s: float = field(metadata=_rng(0.01, 10.0))
    enable_timeout_s: float = field(metadata=_rng(0.01, 10.0))  #: CiA 402 power-up to Operation enabled
    vendor_id: int = field(metadata=_rng(0, 0xFFFF_FFFF))  #: expected identity 0x1018:01
    product_code: int = field(metadata=_rng(0, 0xFFFF_FFFF))  #: expected identity 0x1018:02
    revision_min: int = field(metadata=_rng(0, 0xFFFF_FFFF))  #: lowest accepted 0x1018:03
    eds: str  #: the drives' EDS: a path relative to the profile, or the name of a shipped one
    #: the master's own node id: its heartbeat is 0x700 + this id, the drives consume it (0x1016)
    master_node_id: int = field(default=127, metadata=_rng(1, 127))
    #: the master's heartbeat producer time [s], sent from the master's own loop (proves it is alive)
    master_heartbeat_period_s: float = field(default=0.05, metadata=_rng(0.005, 10.0))
    #: the drives' consumer heartbeat time 0x1016 on the master = factor * master_heartbeat_period_s
    master_heartbeat_consumer_factor: float = field(default=2.5, metadata=_rng(1.5, 10.0))
    #: the rig's other protection against the master's death, stated in words (e.g. "an external
    #: watchdog relay on the master's heartbeat drops STO of both drives within 100 ms"); empty (the
    #: default): the drives' own reaction (consumer heartbeat 0x1016 + abort connection option 0x6007)
    #: is required, and a drive that lacks or refuses it stops the preflight
    external_watchdog: str = ""
    #: how the EMAs hold a force: "auto" (CST where the drive offers it, else "csp"), "cst" (the drive's
    #: cyclic synchronous torque mode, 0x6071), "csp" (the master's own force loop in CSP)
    force_control: str = "auto"
    #: an object of the drives that reports the gear ratio i_total [rad/mm] (REAL32), compared in the
    #: preflight with mechanics.i_total_rad_per_mm; "" (the default): the drives report none
    gear_ratio_object: str = ""
    #: the serial number (0x1018:04) of each EMA's drive, pinned to this rig's actuators; 0 (the default):
    #: not pinned. ``emacheck commission`` names a drive that reports another one (docs/commission.md)
    serial_ema1: int = field(default=0, metadata=_rng(0, 0xFFFF_FFFF))
    serial_ema2: int = field(default=0, metadata=_rng(0, 0xFFFF_FFFF))
    #: a mode change (0x6060) must show in the modes display 0x6061 within this [s]
    mode_change_timeout_s: float = field(default=0.1, metadata=_rng(0.004, 10.0))
    #: fault resets tried on a drive found in FAULT at power-up before the check is refused
    fault_reset_attempts: int = field(default=3, metadata=_rng(1, 10))
    #: from QUICK STOP ACTIVE the master commands disable voltage once the drive stands still, or at
    #: the latest after this [s]
    quick_stop_timeout_s: float = field(default=1.0, metadata=_rng(0.01, 10.0))
    #: the master's-death drill (docs/drives.md) runs before every check; a sentence here saying why
    #: skips it (quoted in the run folder and the report); "" (the default) runs it
    skip_master_loss_drill: str = ""

    @property
    def node_ids(self) -> tuple[int, int]:
        return (self.node_id_ema1, self.node_id_ema2)

    @property
    def master_consumer_time_s(self) -> float:
        """The drives' consumer heartbeat time on the master's heartbeat [s], whole milliseconds
        as written to 0x1016 (factor times the master's period, rounded to the ms)."""
        return round(self.master_heartbeat_consumer_factor * self.master_heartbeat_period_s * 1000.0) / 1000.0


#: The most characters of an identity text a check records (``--aircraft``, ``--position``, ``--rig``,
#: ``--operator``, ``--work-order``, the profile's ``history.aircraft``/``position``/``rig``): longer is refused.
#: Derived from what the identifiers need: an aircraft registration is at most 7 characters (ICAO flight plan,
#: item 7; 8 with the hyphen painted on the aircraft, D-EMAX), a part number at most 32 and a serial number at
#: most 15 (ATA Spec 2000, chapter 9, text elements PNR and SER); free text (a position such as "left aileron,
#: outboard actuator", a name) needs more than an identifier. 64 is twice the longest identifier, the line length
#: of IATA's teletype messages, and one line of the sign-off box's value column printed on A4 at 9 pt (about 130
#: mm, some 70 average characters): nothing a check records needs more, and a longer text is a mistake (a pasted
#: paragraph, a path) rather than an identity (docs/report.md, *Identity texts*).
IDENTITY_MAX_CHARS = 64


@dataclass(frozen=True)
class HistorySettings:
    """``[history]`` of an actuation profile (optional): where the checks are recorded and what
    the record says about the installation, unless ``--history``, ``--aircraft``, ``--position``
    and ``--rig`` say otherwise (docs/history.md)."""

    #: the station's history database (``sqlite:///PATH`` or ``postgresql://USER@HOST/DB``);
    #: "" (the default): an SQLite file in the user's data directory
    url: str = ""
    aircraft: str = ""  #: the aircraft's registration, e.g. "D-AXYZ"
    position: str = ""  #: where the actuation sits on it, e.g. "left aileron"
    rig: str = ""  #: the test rig or station that runs the check


@dataclass(frozen=True)
class Actuation:
    """The actuation as the master and the analysis see it (profiles/actuation.toml)."""

    name: str
    mechanics: Mechanics
    sensors: Sensors
    timing: Timing
    canopen: Canopen
    history: HistorySettings = field(default_factory=HistorySettings)
    #: where each signal of the check lives (``[signals.ema1]``, ``[signals.ema2]``, ``[nodes.NAME]``);
    #: set by :func:`hil.profile.load.load_actuation`
    signals: SignalMap | None = None

    @property
    def sample_rate_Hz(self) -> float:
        return 1.0 / self.timing.sync_period_s


# -------------------------------------------------------------------- check

#: Hard caps that no check profile can raise, as fractions or absolute values.
#: A profile value above its cap is refused at load naming the field, and the
#: supervisor applies ``min(profile value, cap)`` again at run time.
HARD_FORCE_FIGHT_FRACTION = 0.15  #: force fight at most 15 % of F_limit (paper 2.1)
HARD_MAX_FORCE_FRACTION = 0.25  #: any EMA force at most 25 % of F_limit during the check
HARD_MAX_FORCE_FIGHT_FRACTION = 0.20  #: measured force-fight level |F1 - F2| / 2 at most 20 % of F_limit
HARD_MAX_FORCE_IMBALANCE_FRACTION = 0.10  #: |F1 + F2| (load cells disagree) at most 10 % of F_limit
HARD_MAX_VELOCITY_MM_PER_S = 50.0
HARD_MAX_FOLLOWING_ERROR_MM = 2.0
HARD_MAX_D_INT_MM = 2.0
HARD_LVDT_GAIN_TOLERANCE = 0.10  #: D plausibility allows this LVDT pitch error (the paper's is 7.5 %)
HARD_MAX_STALE_CYCLES = 5  #: SYNC cycles a sample may be missing before it is stale (drives keeping no limits)
#: the freshness limit where the drives keep their limits themselves [ms] (docs/safety.md, *A stall of the
#: master*): a ceiling independent of the profile's physics terms, which set the value below it at run time
#: (e / v, the undetected motion v t <= e, from this run's own e and v; C - P_hb - 2 T from its heartbeats):
#: the master is never blind longer than the rig's independent stop path on the master's loss is assumed to
#: take (docs/drives.md section 5: a watchdog relay drops STO 100 ms after the master's last heartbeat).
#: (It was 2 mm / 50 mm/s = 40 ms, e / v at the two caps: one point of e / v, not a bound of anything.)
HARD_MAX_STALE_MS = 100.0
HARD_MAX_FROZEN_CYCLES = 100  #: cycles a noisy sensor may repeat the same value
HARD_MAX_LAG_S = 0.5  #: longest a received frame may wait before the master takes it [s]


@dataclass(frozen=True)
class Approach:
    speed_mm_per_s: float = field(metadata=_rng(0.0, 20.0, lo_open=True, hard_max=20.0))
    settle_s: float = field(metadata=_rng(0.0, 60.0))


@dataclass(frozen=True)
class CalibrationStep:
    sweep_speed_mm_per_s: float = field(metadata=_rng(0.0, 20.0, lo_open=True, hard_max=20.0))
    sweep_amplitude_mm: float = field(metadata=_rng(0.0, 200.0, lo_open=True))
    opposing_force_N: float = field(metadata=_rng(0.0, 1e5, lo_open=True))
    force_ramp_s: float = field(metadata=_rng(0.0, 60.0, lo_open=True))


@dataclass(frozen=True)
class ForceFightStep:
    amplitude_fraction_of_limit: float = field(
        metadata=_rng(0.0, 1.0, lo_open=True, hard_max=HARD_FORCE_FIGHT_FRACTION))
    cycles: int = field(metadata=_rng(1, 50))
    force_rate_N_per_s: float = field(metadata=_rng(0.0, 1e5, lo_open=True))
    loop_gain_mm_per_N_s: float = field(metadata=_rng(0.0, 1.0, lo_open=True))
    max_excursion_rate_mm_per_s: float = field(metadata=_rng(0.0, 5.0, lo_open=True, hard_max=5.0))


@dataclass(frozen=True)
class Safety:
    """Supervisor limits of the check (profile ``[safety]``); each is capped by a hard constant."""

    max_force_N: float = field(metadata=_rng(0.0, 1e6, lo_open=True))
    max_stroke_mm: float = field(metadata=_rng(0.0, 200.0, lo_open=True))
    max_velocity_mm_per_s: float = field(
        metadata=_rng(0.0, 1e3, lo_open=True, hard_max=HARD_MAX_VELOCITY_MM_PER_S))
    max_following_error_mm: float = field(
        metadata=_rng(0.0, 10.0, lo_open=True, hard_max=HARD_MAX_FOLLOWING_ERROR_MM))
    max_d_int_mm: float = field(metadata=_rng(0.0, 10.0, lo_open=True, hard_max=HARD_MAX_D_INT_MM))
    #: force-fight level |F1 - F2| / 2 (hard cap HARD_MAX_FORCE_FIGHT_FRACTION of F_limit)
    max_force_fight_N: float = field(default=7000.0, metadata=_rng(0.0, 1e6, lo_open=True))
    #: load-cell plausibility |F1 + F2| (hard cap HARD_MAX_FORCE_IMBALANCE_FRACTION of F_limit)
    max_force_imbalance_N: float = field(default=2500.0, metadata=_rng(0.0, 1e6, lo_open=True))
    #: sensor freshness where a drive keeps its limits only partly or not at all (hil/check/staleness.py): SYNC
    #: cycles in a row without a complete sample
    max_stale_cycles: int = field(default=2, metadata=_rng(1, 1000, hard_max=HARD_MAX_STALE_CYCLES))
    #: sensor freshness: cycles a noisy LVDT or load cell may repeat exactly the same value
    max_frozen_cycles: int = field(default=25, metadata=_rng(3, 10_000, hard_max=HARD_MAX_FROZEN_CYCLES))
    #: sensor freshness where both drives keep their stroke, torque and speed limits themselves [ms] (the
    #: master's stall budget, hil/check/staleness.py; at run time also at most HARD_MAX_STALE_MS, the drives'
    #: consumer heartbeat time minus one master heartbeat period and 2 SYNC periods, and the following error over
    #: the speed limit; the default is that last term of the shipped profile, 0.5 mm / 10 mm/s = 50 ms)
    max_stale_ms: float = field(default=50.0, metadata=_rng(0.0, 10_000.0, lo_open=True, hard_max=HARD_MAX_STALE_MS))
    #: master lag: the longest a SYNC may wait in the master's socket before it is taken [s]
    #: (the master fell behind the bus, or the computer stalled); real bus only
    max_lag_s: float = field(default=0.02, metadata=_rng(0.0, 10.0, lo_open=True, hard_max=HARD_MAX_LAG_S))


def _floor(kind: str) -> float:
    return field(default=DUAL_FLOORS[kind], metadata=_rng(0.0, lo_open=True))


@dataclass(frozen=True)
class DiagnosisFloors:
    """Relevance floors of ``emacheck diagnose --reference`` with the dual-EMA model (check profile
    ``[diagnosis]``): a change is named only above its floor. Defaults: measured on simulated rigs
    (:data:`hil.profile.floors.DUAL_FLOORS`, docs/diagnose.md); a real rig states its own."""

    play_um: float = _floor("play_um")  #: internal play and LVDT offset, um
    external_play_um: float = _floor("external_play_um")  #: external play (both bearings' sum), um
    stiffness_pct: float = _floor("stiffness_pct")  #: contact stiffness, %
    compliance_pct: float = _floor("compliance_pct")  #: bearing-plus-housing compliance, %
    sensor_gain_pct: float = _floor("sensor_gain_pct")  #: LVDT pitch, %
    friction_N: float = _floor("friction_N")  #: hinge and drives' friction at the check's speed, N
    loadcell_gain_pct: float = _floor("loadcell_gain_pct")  #: load cell gain, %
    ema_friction_N: float = _floor("ema_friction_N")  #: extra friction at one EMA (Coulomb, viscous, asymmetric), N
    stribeck_N: float = _floor("stribeck_N")  #: static friction above Coulomb at one EMA, N
    lvdt_linearity_um: float = _floor("lvdt_linearity_um")  #: LVDT bow and S over the stroke, um
    lvdt_drift_pct_per_h: float = _floor("lvdt_drift_pct_per_h")  #: LVDT gain drift, %/h
    time_skew_ms: float = _floor("time_skew_ms")  #: resolver-LVDT time skew, ms
    progressive_pct_per_mm: float = _floor("progressive_pct_per_mm")  #: progressive stiffness, %/mm
    viscoelastic_N_per_mm: float = _floor("viscoelastic_N_per_mm")  #: visco-elastic stiffness, N/mm


@dataclass(frozen=True)
class Check:
    """The automated check (profiles/check.toml)."""

    approach: Approach
    calibration: CalibrationStep
    force_fight: ForceFightStep
    safety: Safety
    diagnosis: DiagnosisFloors = field(default_factory=DiagnosisFloors)
