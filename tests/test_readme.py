"""The README's validation table is the code's own output."""

import re
from pathlib import Path

from symtrack import validation
from symtrack.runner import run, summarise
from symtrack.scenario import load_scenario


def test_readme_validation_table_matches_the_code():
    text = Path("README.md").read_text()
    m = re.search(r"<!-- validation-table:start -->\n(.*?)<!-- validation-table:end -->", text, re.S)
    assert m, "README has no validation table markers"
    summary = summarise(run(load_scenario("validation"), progress=False))
    assert m.group(1) == validation.table_markdown(summary)
