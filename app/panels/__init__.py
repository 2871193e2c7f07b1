"""The docked panels of the viewer window, one module a panel (:mod:`.pose`, :mod:`.view`,
:mod:`.neural`, :mod:`.vocab`), listed with their dock spaces in :mod:`.registry`. Each
draws from the viewer's shared state (:class:`texvocab_viewer.viewer.Viewer`)."""
