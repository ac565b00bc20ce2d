"""The README's Python examples run as written (doctest on its ```pycon blocks)."""

from __future__ import annotations

import doctest
import re

import pytest

from conftest import REPO


def blocks():
    text = (REPO / "README.md").read_text()
    section = text.split("## Python", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```pycon\n(.*?)```", section, flags=re.S)


def test_readme_has_python_examples():
    assert len(blocks()) >= 2


@pytest.mark.parametrize("index", range(len(blocks())))
def test_readme_example(index):
    source = blocks()[index]
    if "trimesh" in source:
        pytest.importorskip("trimesh", reason="SKIPPED: the README's trimesh example needs trimesh (pip install trimesh)")
    test = doctest.DocTestParser().get_doctest(source, {}, f"README.md python block {index}", "README.md", 0)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted > 0
