"""``pipeline/od/samples.groups``: the passes of a day of samples by integer codes equal
the Python grouping it replaced (``sorted(set(zip(...)))`` and a boolean mask per key)."""

import numpy as np

from trackproc.pipeline.od.samples import groups


def _reference(*columns):
    cols = [np.asarray(c).astype(str) for c in columns]
    out = []
    for key in sorted(set(zip(*cols))):
        mask = np.ones(cols[0].size, bool)
        for col, part in zip(cols, key):
            mask &= col == part
        out.append((key, np.flatnonzero(mask)))
    return out


def test_groups_equal_the_sorted_tuples_and_their_masks():
    rng = np.random.default_rng(7)
    n = 3000
    # names whose sorted order is not their length's or their numbers' ("KIR-10" < "KIR-9"), a
    # capital before a small letter, non-ASCII, the empty string, several widths
    station = rng.choice(np.array(["KIR", "MAD", "ZHY", "kir", "Zhōng", ""], dtype=object), n)
    pass_id = rng.choice(np.array([f"P-{k}" for k in (1, 2, 9, 10, 11, 100)], dtype=object), n)
    kind = rng.choice(np.array(["range", "range_rate", "doppler"], dtype=object), n)
    for cols in ((station, pass_id, kind), (station, pass_id), (station,)):
        ours, theirs = groups(*cols), _reference(*cols)
        assert [k for k, _ in ours] == [k for k, _ in theirs]
        for (_, a), (_, b) in zip(ours, theirs):
            np.testing.assert_array_equal(a, b)
    assert groups(np.array([], dtype=object)) == []
    sub = np.flatnonzero(rng.random(n) > 0.3)                   # a subset, as the kept rows
    assert [k for k, _ in groups(station[sub], kind[sub])] == [k for k, _ in _reference(station[sub], kind[sub])]


def test_groups_of_columns_that_are_not_strings_are_their_texts():
    """Numbers or a None in a column group as their text does (``astype(str)``): 10 sorts before 9."""
    numbers = np.array([9, 10, 1, 10, 9], dtype=object)
    mixed = np.array(["KIR", None, "KIR", "MAD", None], dtype=object)
    fixed = np.array(["b", "a", "b", "a", "c"])                  # numpy text, not objects
    for cols in ((numbers,), (mixed, numbers), (fixed, mixed)):
        ours, theirs = groups(*cols), _reference(*cols)
        assert [k for k, _ in ours] == [k for k, _ in theirs] and all(isinstance(p, str) for k, _ in ours for p in k)
        for (_, a), (_, b) in zip(ours, theirs):
            np.testing.assert_array_equal(a, b)
