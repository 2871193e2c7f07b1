"""texvocab's desktop viewer (moderngl + imgui-bundle), installed as ``texvocab_viewer``:
``python -m texvocab_viewer [SOURCE]`` or ``texvocab view``. It sees texvocab through the
public API (``texvocab.pipeline``, ``texvocab.errors``) only.

Layers, each importing only from those below it (an import-linter contract): the command
line (:mod:`.launch`) > the scripted runs of tests and benchmarks (:mod:`.testing`) > the
window (:mod:`.window`) > the state its panels share (:mod:`.viewer`) > the panels
(:mod:`.panels`) > exports (:mod:`.export`) and the neural render (:mod:`.neural`) > GL
(:mod:`.gl`) > the edited pose and loaded data (:mod:`.state`, :mod:`.posing`) > file
dialogs and command-line defaults (:mod:`.dialogs`, :mod:`.arguments`).
"""
