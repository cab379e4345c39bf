"""What the plots share: matplotlib on the Agg backend (imported when a plot is drawn), the
display transform of renders and the line style per sampler."""
from __future__ import annotations

import numpy as np

SAMPLER_STYLE = {"dcos": "--", "vndf": "-", "vcavity": ":", "own": "-", "native": "-",
                 "dcos + native": "-.", "vndf + native": "-."}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def to_display(image):
    return np.clip(np.nan_to_num(image[..., :3]), 0.0, 1.0) ** (1.0 / 2.2)
