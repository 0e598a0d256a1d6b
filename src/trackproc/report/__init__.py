"""The report layer: figures and text for people, from the plain results of ``pipeline``.

Between ``cli`` and ``pipeline`` in the layer contract: nothing below imports it. Angles are
shown in degrees, every axis names its unit, legends sit outside the data, lines break at data
gaps (``plots.break_gaps``), figures are saved with a tight bounding box (``plots.encode``: the
tests check there that no text is clipped), and matplotlib (the optional ``plot`` extra,
``pip install 'trackproc[plot]'``) is imported only when a figure is drawn.
"""
