"""The error budget of paper 2.3 in result.json / serv.json form (shared by the maint and serv analyses)."""

from __future__ import annotations

from blf.maint import AccuracyBudget

PAPER_PITCH_ERROR = 0.075  #: the paper's uncompensated pitch error, used when no calibration says otherwise


def budget_dict(b: AccuracyBudget) -> dict:
    def m(x):
        return {"travel_mm": x.travel_mm, "pitch_uncompensated_mm": x.pitch_uncompensated_mm,
                "pitch_compensated_mm": x.pitch_compensated_mm, "noise_mm": x.noise_mm, "jump_mm": x.jump_mm,
                "temperature_mm": x.temperature_mm, "total_compensated_mm": x.total_compensated_mm,
                "total_uncompensated_mm": x.total_uncompensated_mm}
    return {"stroke_mm": b.stroke_mm, "pitch_error": b.pitch_error, "residual_pitch_error": b.residual_pitch_error,
            "lvdt_noise_std_mm": b.lvdt_noise_std_mm, "filtered_noise_std_mm": b.filtered_noise_std_mm,
            "temperature_error": b.temperature_error, "backlash_mm": b.backlash_mm, "target_mm": b.target_mm,
            "BLFmaint": m(b.maint), "BLFserv_paper": m(b.serv_paper), "BLFserv_improved": m(b.serv_improved)}
