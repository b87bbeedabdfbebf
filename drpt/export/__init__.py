"""Exporters: the drpt :class:`~drpt.scene.model.Scene` in other renderers' terms.

Only Mitsuba 3 for now (:mod:`drpt.export.mitsuba`), the ground truth drpt's
renders are checked against.
"""

from drpt.export.mitsuba import to_mitsuba_dict, write_xml

__all__ = ["to_mitsuba_dict", "write_xml"]
