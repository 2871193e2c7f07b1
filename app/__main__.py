"""``python -m texvocab_viewer [SOURCE] ...``: the viewer window (texvocab_viewer.launch)."""

import sys

from texvocab_viewer.launch import main

sys.exit(main())
