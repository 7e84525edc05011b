"""What the two FMUs of ``symtrack export fmu`` share (symtrack/codegen/fmu.py: the homogeneous vehicle;
symtrack/codegen/engine_fmu.py: the vehicle on the terrain engine): the variable record, the units' SI
base units, the FMI 2.0 headers, the log categories, the zip writer and the output probe."""

from __future__ import annotations

import dataclasses
import io
import os
import tempfile
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from ..foundations.errors import ScenarioError

__all__ = ["BASE_UNITS", "FMI2_HEADERS", "LOG_CATEGORIES", "FmuVariable", "probe_writable", "scalar_variable_xml",
           "unit_definitions", "xml_number", "zip_bytes"]

FMI2_HEADERS = tuple(Path(__file__).resolve().parent / "fmi2" / n
                     for n in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"))
LOG_CATEGORIES = ("logStatusError", "logStatusWarning", "logAll")

# SI base units of the units the names carry (FMI 2.0 <BaseUnit>); "N/m^(n+1)" and "N/m^(n+2)" depend on
# the Bekker exponent n and are declared without one
BASE_UNITS = {
    "m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "m/s^2": {"m": 1, "s": -2}, "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1}, "N m": {"kg": 1, "m": 2, "s": -2}, "N": {"kg": 1, "m": 1, "s": -2},
    "Pa": {"kg": 1, "m": -1, "s": -2}, "kg": {"kg": 1}, "kg m^2": {"kg": 1, "m": 2}, "s": {"s": 1},
    "h/km": {"s": 1, "m": -1, "factor": 3.6}, "Pa/m": {"kg": 1, "m": -2, "s": -2}, "kg/m^2": {"kg": 1, "m": -2},
    "Pa s/m": {"kg": 1, "m": -2, "s": -1}, "W": {"kg": 1, "m": 2, "s": -3},
    "kPa": {"kg": 1, "m": -1, "s": -2, "factor": 1000.0}, "Mg/m^3": {"kg": 1, "m": -3, "factor": 1000.0},
    "kg/kg": {}, "mm": {"m": 1, "factor": 0.001}, "deg": {"rad": 1, "factor": 0.017453292519943295},
    "kN": {"kg": 1, "m": 1, "s": -2, "factor": 1000.0}, "J": {"kg": 1, "m": 2, "s": -2},
}


@dataclasses.dataclass(frozen=True)
class FmuVariable:
    """One scalar variable of the FMU (a ScalarVariable of modelDescription.xml)."""

    name: str
    value_reference: int
    causality: str  # input, parameter, output
    variability: str  # continuous, fixed
    start: float | None
    unit: str  # "1": dimensionless (no unit attribute)
    description: str
    initial: str | None = None
    low: float | None = None  # the range the modelDescription gives (min, max; None: none)
    high: float | None = None


def xml_number(v: float) -> str:
    return repr(float(v))


def unit_definitions(variables) -> list[str]:
    """The <UnitDefinitions> block's lines for the variables' units."""
    lines = ["  <UnitDefinitions>"]
    for u in sorted({v.unit for v in variables if v.unit != "1"}):
        base = BASE_UNITS.get(u)
        if base is None:
            lines.append(f"    <Unit name={quoteattr(u)}/>")
        else:
            attrs = " ".join(f'{k}="{v}"' for k, v in base.items())
            lines.append(f"    <Unit name={quoteattr(u)}><BaseUnit {attrs}/></Unit>")
    return lines + ["  </UnitDefinitions>"]


def scalar_variable_xml(v) -> list[str]:
    """The modelDescription lines of one Real :class:`FmuVariable` (both FMUs' ``<ModelVariables>``)."""
    attrs = [f"name={quoteattr(v.name)}", f'valueReference="{v.value_reference}"',
             f"description={quoteattr(v.description)}", f'causality="{v.causality}"',
             f'variability="{v.variability}"']
    if v.initial:
        attrs.append(f'initial="{v.initial}"')
    real = [f"unit={quoteattr(v.unit)}"] if v.unit != "1" else []
    if v.start is not None:
        real.append(f'start="{xml_number(v.start)}"')
    if v.low is not None:
        real.append(f'min="{xml_number(v.low)}"')
    if v.high is not None:
        real.append(f'max="{xml_number(v.high)}"')
    return [f"    <!-- {v.value_reference + 1} -->", f"    <ScalarVariable {' '.join(attrs)}>",
            f"      <Real {' '.join(real)}/>".replace("<Real />", "<Real/>"), "    </ScalarVariable>"]


def zip_bytes(members: dict[str, bytes]) -> bytes:
    """The FMU archive of ``members`` (name -> bytes; a fixed date, the .so executable)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
            zf.writestr(info, data)
    return buf.getvalue()


def probe_writable(path: Path) -> None:
    """Create and remove a file beside ``path`` (permission bits do not tell for root or special file systems)."""
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
    except OSError as err:
        raise ScenarioError(f"--out {str(path)!r}: cannot write into {str(folder)!r} ({err.strerror})") from err
    os.close(fd)
    os.unlink(probe)


