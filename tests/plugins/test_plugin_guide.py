"""The plugin guide's result-type examples run as written (docs/plugin-authoring.md)."""

from __future__ import annotations

import re
from pathlib import Path

import scipy.sparse as sp

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "plugin-authoring.md"
HEADING = "### What a plugin is given, and the result types it builds"


def _section_code() -> str:
    text = GUIDE.read_text()
    section = text[text.index(HEADING):]
    section = section[:section.index("\n### ", len(HEADING))]
    [code] = re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)
    return code


def test_the_result_type_constructors_run_as_the_guide_shows():
    namespace: dict[str, object] = {}
    exec(compile(_section_code(), str(GUIDE), "exec"), namespace)  # noqa: S102
    assert namespace["found"].detector == "doorways"


def test_the_guide_names_the_real_matrix_type():
    from adpart.envs.registry import get_domain

    mdp = get_domain("two-rooms").mdp()
    assert isinstance(mdp.P, sp.csr_array) and not hasattr(mdp.P, "getrow")
    assert isinstance(mdp.as_smdp().F, sp.csr_array)
    text = GUIDE.read_text()
    assert "`mdp.P` is a `scipy.sparse.csr_array`" in text and "no `getrow()`" in text
