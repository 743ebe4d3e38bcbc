"""The progress bar a person watches: drawn on any terminal, also one that reports no size."""

import os
import pty
import subprocess
import sys

CHILD = """
import os
from fusionbench.files.progress import terminal_bar
print(tuple(os.get_terminal_size(2)), flush=True)
bar = terminal_bar(3, "runs", disable=False)
bar.update(3)
bar.close()
"""


def test_the_bar_is_drawn_on_a_terminal_that_reports_no_size():
    master, slave = pty.openpty()  # a fresh pseudo-terminal is 0 x 0, as under `script` and many CI runners
    child = subprocess.run([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, stderr=slave, text=True,
                           timeout=60)
    os.close(slave)
    drawn = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the other side is closed
            break
        if not chunk:
            break
        drawn += chunk
    os.close(master)
    assert child.returncode == 0
    assert child.stdout.strip() == "(0, 0)"  # the case that matters: tqdm alone hides its bar there
    assert "runs: 100%" in drawn.decode() and "3/3" in drawn.decode()
