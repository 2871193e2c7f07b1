"""Errors that reach the user as one clear line (the CLI prints ``error: <message>``)."""


class TexvocabError(Exception):
    """Base class: a problem with the user's input that the message fully explains."""


class AssetError(TexvocabError, ValueError):
    """A file or array does not match what assets_spec/ says it must contain."""


class PoseError(TexvocabError, ValueError):
    """A pose, translation or shape vector has the wrong shape or non-finite values."""
