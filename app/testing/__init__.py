"""Scripted runs of the real viewer window for the tests and benchmarks (``python -m
texvocab_viewer SOURCE --script NAME --report R.json [--screenshot S.png]``).

Scripts that act like a user run inside the ImGui Test Engine (they move sliders and
click widgets by their IDs, as a person would with the mouse); the benchmark uses a
per-frame driver instead so the engine adds nothing to the frame times. Every script
writes a JSON report and exits the app; the last frame goes to ``--screenshot``.
:mod:`.registry` names them all; the window knows only its ``Script`` interface.
"""
