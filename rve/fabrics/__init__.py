"""Fabric generators: woven and knitted RVEs as fibrils with designed initial states."""
from .fabric import SIDES, EndTag, Fabric, Yarn, hex_stack_offsets, minimal_rotation
from .knit import CurveFrame, frenet_directors, knit, knit_curve
from .weave import (
    WEAVE_PATTERNS,
    basket_weave,
    float_lengths,
    plain_weave,
    twill_pattern,
    twill_weave,
    weave,
)

__all__ = [
    "SIDES",
    "WEAVE_PATTERNS",
    "CurveFrame",
    "EndTag",
    "Fabric",
    "Yarn",
    "basket_weave",
    "float_lengths",
    "frenet_directors",
    "hex_stack_offsets",
    "knit",
    "knit_curve",
    "minimal_rotation",
    "plain_weave",
    "twill_pattern",
    "twill_weave",
    "weave",
]
