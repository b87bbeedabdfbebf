"""What a new user meets on the command line: error lines that name the right
``--help`` and the flag meant, one rule for abbreviations, notes for flags that
do nothing, one rule for output folders."""

from __future__ import annotations

import pytest

from conftest import SCENES
from drpt.cli import main

CORNELL = str(SCENES / "cornellbox" / "cornellbox.txt")


def _error(capsys, args):
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_unknown_flag_names_the_command_s_help_and_the_flag_meant(capsys):
    err = _error(capsys, ["render", CORNELL, "--sizee", "64", "64"])
    assert err.startswith("drpt: error: render: unrecognized arguments: --sizee 64 64"), err
    assert "did you mean --size?" in err and err.endswith("(see drpt render --help)"), err
    err = _error(capsys, ["compare", CORNELL, "--controll"])
    assert "did you mean --control?" in err and "(see drpt compare --help)" in err, err
    err = _error(capsys, ["rendr", CORNELL])
    assert "did you mean render?" in err and err.endswith("(see drpt --help)"), err


@pytest.mark.parametrize("flag, meant", [("--sp", "--spp"), ("-Monte", "-MonteCarlo"),
                                         ("-cook", "-cook_torrance")])
def test_no_flag_is_abbreviated(capsys, flag, meant):
    """``--sp`` was refused while ``-Monte`` was taken for ``-MonteCarlo``: one rule, none."""
    args = ["render", "-input", CORNELL, "--size", "4", "4", flag]
    if flag == "--sp":
        args.append("2")
    err = _error(capsys, args)
    assert "unrecognized argument" in err and f"did you mean {meant}?" in err, err


def test_attached_values_of_one_letter_flags_still_work(tmp_path):
    out = tmp_path / "x.exr"
    assert main(["render", CORNELL, "--size", "4", "4", "--spp", "1", f"-o{out}", "-q"]) == 0
    assert out.is_file()


def test_xml_flags_on_a_text_scene_say_they_do_nothing(tmp_path, capsys):
    out = tmp_path / "x.exr"
    assert main(["render", CORNELL, "--size", "4", "4", "--spp", "1", "-o", str(out), "-q",
                 "-D", "spp=4", "--strict"]) == 0
    err = capsys.readouterr().err
    assert "drpt: note: " in err and "-D and --strict apply to Mitsuba XML scenes only" in err, err
    assert main(["render", CORNELL, "--size", "4", "4", "--spp", "1", "-o", str(out), "-q"]) == 0
    assert "note" not in capsys.readouterr().err
