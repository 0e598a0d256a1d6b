"""The estimation core shared by ``refine``, ``estimate``, ``fit-tle`` and ``filter``: the a-priori
(:mod:`.prior`: where its accuracy comes from, its conflict test, its scaling) and the decision to
replace the user's orbit, keep it or decline the data (:mod:`.decision`)."""
