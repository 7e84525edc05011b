"""What both FMU test files share: the scenario's torque programme as fmpy's input table
(:func:`torque_signal`), and a second, independent FMI importer: Renault's fmu-manipulation-toolbox (the dev
extra; https://github.com/grouperenault/fmu_manipulation_toolbox). Its checker validates an FMU's
modelDescription.xml against the FMI 2.0 XSD and its semantic rules; its container is an FMU whose
own C runtime loads another FMU's binary and steps it through the FMI calling sequence (instantiate,
setup, initialisation mode, doStep, terminate): run by fmpy, the container exercises our binary through
a second implementation of that sequence."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

CONTAINER_CLI = "from fmu_manipulation_toolbox.cli.fmucontainer import fmucontainer; fmucontainer()"


def check(fmu_path) -> str:
    """The toolbox's ``-check`` of the FMU: its log; raises AssertionError unless it reports the FMU
    compliant with FMI 2.0 and without semantic error (its exit code 0)."""
    res = subprocess.run([sys.executable, "-m", "fmu_manipulation_toolbox", "-input", str(fmu_path), "-check"],
                         capture_output=True, text=True, timeout=300)
    log = res.stdout + res.stderr
    assert res.returncode == 0, log
    assert "compliant with FMI-2.0" in log and "No semantic error" in log, log
    return log


def container(fmu_path, step_s: float, folder: Path) -> Path:
    """A container FMU around ``fmu_path`` (its inputs and outputs exposed under their own names) that
    steps it every ``step_s``; built in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    inner = folder / Path(fmu_path).name
    shutil.copyfile(fmu_path, inner)
    desc = folder / "container.csv"
    desc.write_text(f"rule;from_fmu;from_port;to_fmu;to_port\nFMU;{inner.name};;;\n")
    res = subprocess.run([sys.executable, "-c", CONTAINER_CLI, "-container", f"{desc.name}:{step_s!r}",
                          "-fmu-directory", str(folder)], capture_output=True, text=True, timeout=300, cwd=folder)
    out = folder / "container.fmu"
    assert res.returncode == 0 and out.is_file(), res.stdout + res.stderr
    return out


def torque_signal(sc, stop_s):
    """The scenario's piecewise-constant torque programme as fmpy's input table: a repeated time is a step
    (fmpy applies the right-hand value at the step's time, after_event=True)."""
    rows = []
    for i, e in enumerate(sc.torque):
        if i > 0:
            prev = sc.torque[i - 1]
            rows.append((e.t_s, prev.left_N_m, prev.right_N_m))
        rows.append((e.t_s, e.left_N_m, e.right_N_m))
    rows.append((stop_s + 1.0, sc.torque[-1].left_N_m, sc.torque[-1].right_N_m))
    return np.array(rows, dtype=[("time", float), ("torque_cmd_left_N_m", float), ("torque_cmd_right_N_m", float)])
