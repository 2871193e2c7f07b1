"""The root choice of a pose file's motion (``texvocab render --root``, ``shot --root``, the
viewer's Root box): its names and help, without torch, for the command line's parsers.
What each does: :func:`texvocab.pipeline.clip_placement.place_motion`."""

ROOTS = ("floor", "in-place", "facing", "recorded")
ROOT_HELP = (
    "floor: the lowest foot on the capture's floor, starting where its subject starts "
    "(default); in-place: the same without the travel; facing: floor, the first frame "
    "facing the camera; recorded: as the file has it"
)
