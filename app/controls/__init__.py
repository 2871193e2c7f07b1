"""What the viewer's panels and menus act through, one idea a module, mixed into
:class:`texvocab_viewer.viewer.Viewer`: the camera (:mod:`.camera`), the File menu and
its dialogs (:mod:`.files`), exports (:mod:`.exports`)."""
