"""Tools around the renderer: each is a ``python -m drpt`` command.

compare (drpt against a Mitsuba reference), converge (error against time),
knobs (cost and error of each quality knob), bench (ray rates and build times
against Mitsuba), profile (where a render spends its time) and gallery (every
bundled scene beside its reference). Every command takes the render flags of
:func:`drpt.cli.args.add_render_flags`. Beside them: :mod:`.reference` (the
committed Mitsuba reference table and the cached, batched Mitsuba render) and
:mod:`.scenegen` (the generators of the bundled scenes). None of the renderer
imports them.
"""
