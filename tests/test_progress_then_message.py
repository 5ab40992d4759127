"""A command stopped while a progress bar is open (Ctrl-C in navigate's smoothing, an error mid-fit):
the one error printer closes the bar first, so its line starts a line of its own (a bar's text
without a newline used to run into it: "navigate: smoothing: 2iteration [...]imu-learn navigate:
interrupted")."""
import io

from tqdm import tqdm

from imu_learn.cli.common import _end_progress


def test_an_open_bar_is_closed_before_the_last_line():
    err = io.StringIO()
    bar = tqdm(desc="navigate: smoothing", unit="iteration", file=err)
    bar.update(2)
    _end_progress()
    err.write("imu-learn navigate: interrupted\n")
    last = err.getvalue().replace("\r", "\n").splitlines()[-1]
    assert last == "imu-learn navigate: interrupted"
    assert not tqdm._instances  # closed, not only moved past

