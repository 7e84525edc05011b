"""Ferretti & Girelli's (1999) reported validation figures (docs/model.md, "Validation case and calibrated
values") and the check against them."""

from __future__ import annotations

__all__ = ["PUBLISHED", "REPORTED", "check", "comparison_markdown", "differences", "table_markdown"]

# the built-in scenario that is the validation case as published (its manoeuvre, vehicle, soil and model)
PUBLISHED = "validation"

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


def differences(scenario) -> list[str]:
    """What sets ``scenario`` apart from the validation case as published (the built-in scenario
    :data:`PUBLISHED`): its vehicle, soil, model options, start, torque programme and stop rule, each
    as ``key = value (published: value)``; empty for the published case. The integrator, its
    tolerances and steps and the terrain's representation (homogeneous or the grid) are how it is
    computed, not what: they are not compared."""
    from ..model.options import scenario_keys
    from ..simulation.scenario import load_scenario

    ref = load_scenario(PUBLISHED)
    out = []

    def differ(key, mine, theirs):
        if mine != theirs:
            out.append(f"{key} = {mine!r} (published: {theirs!r})")

    for section, preset, ref_preset, values, ref_values in (
            ("vehicle", scenario.vehicle_preset, ref.vehicle_preset, scenario.vehicle, ref.vehicle),
            ("soil", scenario.soil_preset, ref.soil_preset, scenario.soil, ref.soil)):
        if preset != ref_preset:
            differ(f"{section}.preset", preset, ref_preset)
            continue
        for k in sorted(set(values) | set(ref_values)):
            differ(f"{section}.{k}", values.get(k), ref_values.get(k))
    for k in scenario_keys():
        differ(f"model.{k}", getattr(scenario.model, k), getattr(ref.model, k))
    for k in ("x_m", "y_m", "yaw_deg"):
        differ(f"start.{k}", getattr(scenario.start, k), getattr(ref.start, k))
    if scenario.torque != ref.torque:
        out.append("the [[torque]] programme (published: 2000 N m on both sprockets, the left one idle from 4 s)")
    for k in ("stop_after_distance_m", "stop_distance_event"):
        differ(f"run.{k}", getattr(scenario.run, k), getattr(ref.run, k))
    return out


def table_markdown(summary: dict, differ: list[str] | None = None) -> str:
    """The reported-against-simulated table. With ``differ`` (:func:`differences`: the run is not
    the case as published) the table says so first and its last column compares, it does not grade."""
    if not differ:
        lines = ["| quantity | reported (Ferretti & Girelli 1999) | simulated | within |",
                 "|---|---|---|---|"]
    else:
        lines = [f"Not the validation case as published: {'; '.join(differ)}. The reported figures belong to "
                 "the published settings, so the last column compares this run with them; it does not grade it.",
                 "", "| quantity | reported (Ferretti & Girelli 1999, published settings) | simulated | "
                 "in the reported range |", "|---|---|---|---|"]
    for key, reported, v, ok in check(summary):
        grade = "yes" if ok else ("no" if differ else "NO")
        lines.append(f"| {key} | {reported} | {_fmt(v)} | {grade} |")
    return "\n".join(lines) + "\n"


def comparison_markdown(declared: dict, other: dict, other_label: str) -> str:
    """The validation table with a second run beside the scenario's own: ``declared`` the summary of
    the scenario as it declares itself (the creep law, the paper's model), ``other`` the summary of
    the same manoeuvre with another setting, labelled ``other_label`` (docs/validation-run.md shows the
    shear law's prediction this way)."""
    lines = [f"| quantity | reported (Ferretti & Girelli 1999) | simulated | within | {other_label} | within |",
             "|---|---|---|---|---|---|"]
    for (key, reported, v, ok), (_, _, w, ok_w) in zip(check(declared), check(other), strict=True):
        lines.append(f"| {key} | {reported} | {_fmt(v)} | {'yes' if ok else 'NO'} | {_fmt(w)} "
                     f"| {'yes' if ok_w else 'NO'} |")
    return "\n".join(lines) + "\n"
