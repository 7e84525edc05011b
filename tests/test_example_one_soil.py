"""examples/one_soil.py at a small size: one soil's row of its table (one pass of the built-in multipass
scenario) and two passes of its second table, through its command line; its column compression against
the closed form of a uniform strain."""

import runpy

import numpy as np
import pytest

EX = runpy.run_path("examples/one_soil.py")


def test_the_column_compression_of_a_uniform_strain_is_the_strain_times_the_depth():
    v0 = 2.0
    v = np.full((3, 4), v0 * (1 - 0.05))  # 5 % vertical strain at every depth
    comp = EX["column_compression_m"](v, v0, (0.1, 0.3, 0.5, 0.8))
    assert comp == pytest.approx(np.full(3, 0.05 * 0.8), rel=1e-12)


def test_the_example_prints_a_soils_row_and_its_passes(capsys):
    assert EX["main"](["--presets", "sandy_loam_15", "--soil", "sandy_loam_15", "--passes", "2"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| sandy_loam_15 |")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    rut_mm, comp_mm, drho = float(cells[7]), float(cells[8]), float(cells[10])
    assert rut_mm > 0 and comp_mm > 0 and drho > 0  # the pass left a rut, compressed and densified the column
    passes = [line for line in out.splitlines() if line.startswith("| 1 |") or line.startswith("| 2 |")]
    assert len(passes) == 2


def test_a_preset_the_check_refuses_gets_its_reason_in_a_row_and_the_table_goes_on(capsys):
    """heavy_clay_wes_40 (Bekker n = 0.11) is refused under the reference crawler's 25 kPa (its law stiffer than
    its elastic reloading there): its row says why, and the example still ends well (the presets' loop of its
    defaults stopped there with exit 1)."""
    assert EX["main"](["--presets", "heavy_clay_wes_40", "--passes", "0"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| heavy_clay_wes_40 |")]
    assert len(rows) == 1 and "refused on load: Bekker's loading stiffness" in rows[0]
    assert "allowed range" in rows[0]
