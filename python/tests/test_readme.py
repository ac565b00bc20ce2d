"""The Python examples of the README and of docs/ run as written (doctest on their ```pycon blocks)."""

from __future__ import annotations

import doctest
import re

import pytest

from conftest import REPO


def blocks():
    """The ```pycon blocks of the README's Python section and of every page of docs/."""
    text = (REPO / "README.md").read_text()
    sections = [text.split("## Python", 1)[1].split("\n## ", 1)[0]]
    sections += [p.read_text() for p in sorted((REPO / "docs").glob("*.md"))]
    found = []
    for section in sections:
        found += re.findall(r"```pycon\n(.*?)```", section, flags=re.S)
    return found


def test_readme_has_python_examples():
    assert len(blocks()) >= 3


@pytest.mark.parametrize("index", range(len(blocks())))
def test_readme_example(index, monkeypatch):
    source = blocks()[index]
    if "trimesh" in source:
        pytest.importorskip("trimesh", reason="SKIPPED: the trimesh example (docs/trimesh.md) needs trimesh (pip install trimesh)")
    if "dask" in source:
        pytest.importorskip("distributed", reason="SKIPPED: the Dask example (docs/more-than-one-machine.md) needs dask (pip install pyraypack[dask])")
    # The examples name the repository's files relative to its root.
    monkeypatch.chdir(REPO)
    test = doctest.DocTestParser().get_doctest(source, {}, f"README.md python block {index}", "README.md", 0)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted > 0
