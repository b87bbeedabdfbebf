"""Tools around the renderer: each is a ``python -m drpt`` command.

compare (drpt against a Mitsuba reference), converge (error against time),
knobs (cost and error of each quality knob), bench (ray rates and build times
against Mitsuba), profile (where a render spends its time) and gallery (every
bundled scene beside its reference). None of the renderer imports them.
"""
