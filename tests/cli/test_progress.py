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
