"""Progress only on a terminal (issue 16): a run over two seconds shows an elapsed-time line on a
TTY's stderr and erases it; in a pipe nothing."""

import io
import time

from trackproc.cli.progress import ticker


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_terminal_sees_progress_then_a_clean_line():
    out = _Tty()
    with ticker("accuracy", stream=out, after_s=0.2):
        time.sleep(0.6)      # the line appears at 0.2 s; one write is all the checks below need
    text = out.getvalue()
    assert "trackproc accuracy: working" in text
    assert text.endswith("\r") and text.rstrip("\r ").count("\r") >= 1


def test_pipe_quiet_short_and_batch_see_nothing():
    # 0.4 s: past after_s = 0.2, where a terminal would see the line
    for stream, kw, command, wait in ((io.StringIO(), {}, "accuracy", 0.4), (_Tty(), {"enabled": False}, "accuracy", 0.4),
                                      (_Tty(), {}, "accuracy", 0.05), (_Tty(), {}, "batch", 0.4)):
        with ticker(command, stream=stream, after_s=0.2, **kw):
            time.sleep(wait)
        assert stream.getvalue() == ""


def test_the_line_is_erased_before_the_summary(monkeypatch):
    """What the command writes to stderr (its summary, a warning) starts on a clean line: the
    progress line is blanked out first, and redrawn only after a complete line."""
    import sys

    out = _Tty()
    monkeypatch.setattr(sys, "stderr", out)
    with ticker("accuracy", after_s=0.05):
        time.sleep(0.3)
        print("summary: 3 passes", file=sys.stderr)
    text = out.getvalue()
    before, after = text.split("summary: 3 passes", 1)
    assert "working" in before
    # what is on screen when the summary starts: the last \r-delimited segment before it is blank
    assert before.endswith("\r") and before.rsplit("\r", 2)[-2].strip() == ""
    assert sys.stderr is out     # the wrapper is gone with the ticker
