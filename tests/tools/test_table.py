"""drpt.tools.table: the markdown tables of the tools' reports."""

import pytest

from drpt.tools.table import markdown_table


def test_markdown_table_lines():
    t = markdown_table(["a", "bb"], [[1, "x"], [2.5, None]])
    assert t == "| a | bb |\n| --- | --- |\n| 1 | x |\n| 2.5 | None |"
    assert markdown_table(["a", "b", "c", "d"], [], align="-lrc").splitlines()[1] == \
        "| --- | :--- | ---: | :---: |"
    assert markdown_table(["a", "b"], [["1", "2"]], padded_rule=False) == \
        "| a | b |\n|---|---|\n| 1 | 2 |"


def test_markdown_table_checks_shape():
    with pytest.raises(ValueError, match="row 1 has 1 cells"):
        markdown_table(["a", "b"], [["1", "2"], ["3"]])
    with pytest.raises(ValueError, match="align"):
        markdown_table(["a", "b"], [], align="r")
    with pytest.raises(ValueError, match="align"):
        markdown_table(["a"], [], align="x")
