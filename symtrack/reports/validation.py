"""Ferretti & Girelli's (1999) reported validation figures (docs/model.md, "Validation case and calibrated
values") and the check against them."""

from __future__ import annotations

__all__ = ["REPORTED", "check", "comparison_markdown", "table_markdown"]

# key in summary.json -> (reported, accepted range (low, high) or None, unit/scale label)
REPORTED = (
    ("distance_after_idle_m", "about 20 m", (19.5, 20.5)),
    ("lateral_deviation_m", "about 8 cm (accepted 4-16 cm)", (0.04, 0.16)),
    ("yaw_final_deg", "0 to about 0.4 deg (accepted 0.2-0.8)", (0.2, 0.8)),
    ("sinkage_sprocket_mm", "about 1-2 mm", (1.0, 2.0)),
    ("sinkage_idler_mm", "about 1-2 mm", (1.0, 2.0)),
    ("shear_driven_max_m", "order 1-10 cm (paper 10 cm, thesis 10 mm)", (0.005, 0.15)),
    ("shear_idle_min_m", "negative", (-1.0, -1e-6)),
    ("nose_up", "nose up: rear (sprocket) sinks more", None),
)


def check(summary: dict) -> list[tuple[str, str, object, bool]]:
    rows = []
    for key, reported, rng in REPORTED:
        v = summary.get(key)
        ok = bool(v) if rng is None else (v is not None and rng[0] <= v <= rng[1])
        rows.append((key, reported, v, ok))
    return rows


def _fmt(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def table_markdown(summary: dict) -> str:
    lines = ["| quantity | reported (Ferretti & Girelli 1999) | simulated | within |",
             "|---|---|---|---|"]
    for key, reported, v, ok in check(summary):
        lines.append(f"| {key} | {reported} | {_fmt(v)} | {'yes' if ok else 'NO'} |")
    return "\n".join(lines) + "\n"


def comparison_markdown(declared: dict, other: dict, other_label: str) -> str:
    """The validation table with a second run beside the scenario's own: ``declared`` the summary of
    the scenario as it declares itself (the creep law, the paper's model), ``other`` the summary of
    the same manoeuvre with another setting, labelled ``other_label`` (the README shows the shear
    law's prediction this way)."""
    lines = [f"| quantity | reported (Ferretti & Girelli 1999) | simulated | within | {other_label} | within |",
             "|---|---|---|---|---|---|"]
    for (key, reported, v, ok), (_, _, w, ok_w) in zip(check(declared), check(other), strict=True):
        lines.append(f"| {key} | {reported} | {_fmt(v)} | {'yes' if ok else 'NO'} | {_fmt(w)} "
                     f"| {'yes' if ok_w else 'NO'} |")
    return "\n".join(lines) + "\n"
