"""What a new user meets on the command line: error lines that name the right
``--help`` and the flag meant, one rule for abbreviations, notes for flags that
do nothing, one rule for output folders."""

from __future__ import annotations

import pytest

from drpt.cli import main


def _error(capsys, args):
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_unknown_flag_names_the_command_s_help_and_the_flag_meant(capsys, cornell):
    err = _error(capsys, ["render", str(cornell), "--sizee", "64", "64"])
    assert err.startswith("drpt: error: render: unrecognized arguments: --sizee 64 64"), err
    assert "did you mean --size?" in err and err.endswith("(see drpt render --help)"), err
    err = _error(capsys, ["compare", str(cornell), "--controll"])
    assert "did you mean --control?" in err and "(see drpt compare --help)" in err, err
    err = _error(capsys, ["rendr", str(cornell)])
    assert "did you mean render?" in err and err.endswith("(see drpt --help)"), err


@pytest.mark.parametrize("flag, meant", [("--sp", "--spp"), ("-Monte", "-MonteCarlo"),
                                         ("-cook", "-cook_torrance")])
def test_no_flag_is_abbreviated(capsys, flag, meant, cornell):
    """``--sp`` was refused while ``-Monte`` was taken for ``-MonteCarlo``: one rule, none."""
    args = ["render", "-input", str(cornell), "--size", "4", "4", flag]
    if flag == "--sp":
        args.append("2")
    err = _error(capsys, args)
    assert "unrecognized argument" in err and f"did you mean {meant}?" in err, err


def test_attached_values_of_one_letter_flags_still_work(tmp_path, cornell):
    out = tmp_path / "x.exr"
    assert main(["render", str(cornell), "--size", "4", "4", "--spp", "1", f"-o{out}", "-q"]) == 0
    assert out.is_file()


def test_xml_flags_on_a_text_scene_say_they_do_nothing(tmp_path, capsys, cornell):
    out = tmp_path / "x.exr"
    assert main(["render", str(cornell), "--size", "4", "4", "--spp", "1", "-o", str(out), "-q",
                 "-D", "spp=4", "--strict"]) == 0
    err = capsys.readouterr().err
    assert "drpt: note: " in err and "-D and --strict apply to Mitsuba XML scenes only" in err, err
    assert main(["render", str(cornell), "--size", "4", "4", "--spp", "1", "-o", str(out), "-q"]) == 0
    assert "note" not in capsys.readouterr().err


# ------------------------------------------------------------------ distributed renders
def test_resumed_render_counts_only_the_samples_it_traced(tmp_path, capsys, cornell):
    """After --resume the summary's samples/s counted the checkpoint's samples as rendered
    now (3x too high when two thirds came from it)."""
    from drpt.cli import main as drpt_main
    from drpt.options import RenderOptions
    from drpt.scene import load_scene
    from support.resume import interrupt, interrupted_then_resumed

    out = tmp_path / "x.exr"
    from drpt.backend import policy

    opts = RenderOptions(width=8, height=8, spp=6, chunk_spp=1, progress=False,
                         max_lanes=policy().max_lanes)  # what the command line gives
    job = interrupted_then_resumed(load_scene(str(cornell)), opts, out, after=4)
    assert job.resumed_spp == 4
    assert job.result.samples == 8 * 8 * 2
    interrupt(load_scene(str(cornell)), opts, out, after=4)
    capsys.readouterr()
    flags = ["render", str(cornell), "--size", "8", "8", "--spp", "6", "--chunk-spp", "1", "-o", str(out), "-q"]
    assert drpt_main([*flags, "--resume"]) == 0
    assert "6 spp (4 from the checkpoint, 2 now)" in capsys.readouterr().out
    assert drpt_main(flags) == 0
    assert "from the checkpoint" not in capsys.readouterr().out


def test_workers_left_idle_and_replaced_workers_are_explained(tmp_path, capsys, monkeypatch, cornell):
    import drpt.distributed.job as job_module
    from drpt.distributed.job import Job, WorkerStats, print_workers, run
    from drpt.errors import DrptError
    from drpt.options import RenderOptions
    from drpt.scene import load_scene

    class NoCluster:
        def __init__(self, *a, **k):
            raise DrptError("no cluster in this test")

    monkeypatch.setattr(job_module, "DaskEngine", NoCluster)  # the engine run() starts
    opts = RenderOptions(width=8, height=8, spp=4, progress=False)  # one chunk
    with pytest.raises(DrptError):
        run(load_scene(str(cornell)), opts, tmp_path / "x.exr", workers=2)
    err = capsys.readouterr().err
    assert "the render is 1 chunk for 2 workers: 1 will have nothing to do" in err
    assert "--chunk-spp" in err

    job = Job(None, workers={f"w{i}": WorkerStats(1, 64, 0.1) for i in range(3)},
              requested_workers=2)
    print_workers(job)
    err = capsys.readouterr().err
    assert "3 workers for --workers 2: 1 replaced one that stopped" in err
    job.requested_workers = 3
    print_workers(job)
    assert "replaced" not in capsys.readouterr().err


def test_an_ignored_plugin_is_reported_once(tmp_path, capsys, scenes_dir):
    sensor = scenes_dir.parent / "tests" / "data" / "xml" / "common_sensor.xml"
    scene = tmp_path / "s.xml"
    scene.write_text(f'<scene version="3.0.0"><include filename="{sensor}"/>'
                     '<shape type="sphere"><bsdf type="nosuchbsdf"/></shape>'
                     '<emitter type="constant"/></scene>')
    assert main(["render", str(scene), "--ignore-unsupported", "--spp", "1", "-q",
                 "-o", str(tmp_path / "x.exr")]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "nosuchbsdf" in ln]
    assert len(lines) == 1 and lines[0].startswith("drpt: warning: "), lines


def test_export_and_render_refuse_a_missing_output_folder_alike(tmp_path, capsys, cornell):
    """export made a missing folder where render refuses one: one rule, refuse."""
    for args in (["render", str(cornell), "--size", "4", "4", "--spp", "1", "-o",
                  str(tmp_path / "no" / "x.exr")],
                 ["export", str(cornell), str(tmp_path / "no" / "x.xml")]):
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.endswith(f"folder {tmp_path / 'no'} does not exist"), err
    assert not (tmp_path / "no").exists()
    assert main(["export", str(cornell), str(tmp_path / "x.xml")]) == 0


@pytest.mark.slow
def test_gui_says_what_starts_the_render_and_can_time_out(tmp_path, capsys, cornell):
    """-gui printed only its address: nothing said that "render" or closing the page
    starts the render, and with no browser it waited for ever."""
    pytest.importorskip("viser")
    out = tmp_path / "x.exr"
    assert main(["render", str(cornell), "--size", "8", "8", "--spp", "1", "-o", str(out), "-q",
                 "-gui", "--port", "0", "--gui-timeout", "0.5"]) == 0
    text = capsys.readouterr()
    assert "drpt view: http://" in text.out
    assert '"render" button, or closing the page, starts the render' in text.out
    assert "With no page open after 0.5 s it renders the scene's camera" in text.out
    assert "no page opened the viewer within --gui-timeout 0.5 s" in text.err
    assert out.is_file()
    assert main(["render", str(cornell), "--gui-timeout", "1", "-o", str(out)]) == 2
    assert "--gui-timeout applies to -gui" in capsys.readouterr().err
