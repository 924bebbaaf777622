"""Why a detector gave no (complete) answer: structured codes beside the human message.

Every tracker result and every :class:`pipeline.detect.Detection` carries a
:class:`Failure` code (None when all went well) next to its one-line ``reason``. Code
that acts on a failure (a study classifying why frames fail) reads the code; people
read the message.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Failure"]


class Failure(StrEnum):
    """Failure codes of the detection pipeline, in the order the stages run."""

    IMAGE = "image"
    """The image cannot be used (pixel type, shape, size, or a crop outside the frame)."""
    NO_BLOBS = "no-blobs"
    """Nothing bright enough above the background."""
    NO_SIDE_COLOUR = "no-side-colour"
    """Bright blobs, none of them of a side colour."""
    TOO_FEW_BLOBS = "too-few-blobs"
    """Fewer than five blobs of the most frequent side colour: markers lost or merged."""
    NO_COLOUR_WITH_FIVE = "no-colour-with-five"
    """The study's rule: no colour has exactly five blobs."""
    NO_FIT = "no-fit"
    """Five or more blobs of a colour, but no five of them fit the target's geometry."""
    NUMBERING = "numbering"
    """Five blobs the study's numbering rule cannot order."""
    COLOUR_UNCLEAR = "colour-unclear"
    """Five markers found, but their side colour is unclear."""
    RANGE = "range"
    """Inverse perspective gave no finite positive range."""
    ATTITUDE = "attitude"
    """QUEST gave no finite attitude."""
    POSE = "pose"
    """The perspective-n-point pose could not be solved."""
