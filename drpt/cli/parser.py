"""The ``drpt`` argument parser: drpt's one-line error format, the commands' subparsers."""

from __future__ import annotations

import argparse
import difflib
import re
import sys

from ..scene import xml_flags
from ..tools import bench, compare, converge, gallery, knobs, profile
from .args import add_render_flags, add_view_flags, scene_flags
from .commands import _add_render_args, cmd_export, cmd_render, cmd_view

DESCRIPTION = "Command line: python -m drpt <command> ..."


class _Parser(argparse.ArgumentParser):
    """argparse with drpt's error format: one line, exit status 2 (argparse's
    own prints the whole usage first), naming the command whose ``--help`` to read;
    an unknown flag gets the closest known one ("did you mean"). No flag is
    abbreviated: neither ``--sp`` for ``--spp`` (``allow_abbrev=False``) nor, as
    argparse otherwise allows, ``-Monte`` for ``-MonteCarlo``."""

    def error(self, message: str):
        bad = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if bad:
            close = difflib.get_close_matches(bad.group(1), re.findall(r"'([^']*)'", bad.group(2)),
                                              n=1, cutoff=0.6)
            if close:
                message += f"; did you mean {close[0]}?"
        command = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        print(f"drpt: error: {command}{message} (see {self.prog} --help)", file=sys.stderr)
        sys.exit(2)

    def _get_option_tuples(self, option_string):
        # single-dash flags: only a one-letter flag with its value attached (-Dname=value,
        # -oout.png), never a prefix of a longer flag (argparse's default)
        found = super()._get_option_tuples(option_string)
        if option_string[:2] != "--":
            found = [t for t in found if t[1] == option_string[:2]]
        return found

    def parse_args(self, args=None, namespace=None):
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            target = self
            for action in self._actions:
                if isinstance(action, argparse._SubParsersAction):
                    target = action.choices.get(getattr(ns, "command", None), self)
            target.error(_unrecognized(target, extras))
        return ns


def _unrecognized(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """``unrecognized arguments: ...``, with the closest flag of ``parser`` for each
    unknown flag among them."""
    known = [o for a in parser._actions for o in a.option_strings]
    hints = []
    for arg in extras:
        if arg.startswith("-") and len(arg) > 1:
            name = arg.split("=", 1)[0]
            close = ([o for o in known if o.startswith(name)]
                     or difflib.get_close_matches(name, known, n=1, cutoff=0.6))
            if close:
                hints.append(f"{arg}: did you mean {close[0]}?")
    noun = "argument" if len(extras) == 1 else "arguments"
    return f"unrecognized {noun}: {' '.join(extras)}" + (f" ({'; '.join(hints)})" if hints else "")


def build_parser() -> argparse.ArgumentParser:
    """The ``drpt`` parser: ``render``, ``view``, ``export`` and the tools' commands,
    each with its ``func``."""
    parser = _Parser(prog="drpt", description=DESCRIPTION, allow_abbrev=False)
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render a scene to an image", allow_abbrev=False)
    _add_render_args(render)
    render.set_defaults(func=cmd_render)

    view = sub.add_parser("view", help="look at a scene in the browser, progressively path traced",
                          allow_abbrev=False)
    view.add_argument("scene", help="scene file (the seed's text format, or Mitsuba XML: .xml)")
    view.add_argument("--output", "-o", dest="output", default=None,
                      help="image that the page's \"render\" writes (default <scene>.png)")
    add_render_flags(view)
    add_view_flags(view)
    view.add_argument("--gamma", type=float, default=2.2, help="display gamma (default 2.2)")
    view.set_defaults(func=cmd_view)

    export = sub.add_parser("export", help="write the scene as Mitsuba 3 XML plus meshes",
                            allow_abbrev=False)
    export.add_argument("scene")
    export.add_argument("output", help="the .xml file to write (meshes go beside it)")
    # the flags of render that shape the Mitsuba scene, checked as render checks them
    add_render_flags(export, omit=("seed", "rr_depth", "rr_prob", "accel", "integrator", "mode",
                                   "env_sampling", "max_lanes", "backend", "quiet"))
    export.set_defaults(func=cmd_export)

    for add_parser in (compare.add_parser, gallery.add_parser, profile.add_parser,
                       bench.add_parser, converge.add_parser, knobs.add_parser):
        add_parser(sub)
    return parser


def run(argv: list[str]) -> int:
    """Parse ``argv`` and run its command (user mistakes raise
    :class:`~drpt.errors.DrptError`; flag mistakes exit with status 2)."""
    args = build_parser().parse_args(argv)
    with xml_flags(**scene_flags(args)):
        return args.func(args)
