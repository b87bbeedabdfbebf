"""The interactive preview: ``python -m drpt view`` and ``render -gui``.

:mod:`drpt.view.pose` converts between drpt's camera and viser's camera
pose; :mod:`drpt.view.server` is the viewer (a viser server, a raster of the
scene's geometry, the progressive path-traced frame behind it). viser is the
optional extra ``pip install -e '.[view]'``; only :mod:`drpt.view.server`
imports it.
"""
