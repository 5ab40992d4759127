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



def test_navigates_bar_turned_to_the_batch_pass_is_cleared_when_a_ctrl_c_closes_it():
    """navigate's bar, reset for the batch pass within its delay and shown by each iteration, is cleared
    as the with-block closes it on a Ctrl-C (tqdm took it for never shown and left its text: CI's
    'navigate: smoothing: : 2iteration [...]imu-learn navigate: interrupted')."""
    from imu_learn.fuse.navigate import PROGRESS_DELAY_S, batch_pass_progress

    err = io.StringIO()
    try:
        with tqdm(total=100, desc="navigate", file=err, delay=PROGRESS_DELAY_S, mininterval=1.0, leave=False) as bar:
            bar.update(10)
            step = batch_pass_progress(bar)
            step()
            step()
            shown = err.getvalue()
            assert "navigate: smoothing: 2 iteration" in shown and "smoothing: :" not in shown and "%|" not in shown
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        _end_progress()
        err.write("imu-learn navigate: interrupted\n")
    lines = [ln for ln in err.getvalue().replace("\r", "\n").splitlines() if ln.strip()]
    assert lines[-1] == "imu-learn navigate: interrupted"  # on a line of its own, not after the bar's text
