"""Every option a command's help names is one that command takes: navigate's --bias help once said
"(with --bias-model, the learned one too)", an option only refine has (a user got "unrecognized
arguments"). Config keys (--data.x, --model.x) are the training commands' own and not checked."""
from __future__ import annotations

import re

import pytest

from imu_learn.cli import main

COMMANDS = ("navigate", "refine", "calibrate", "groundtruth", "export", "labels")


@pytest.mark.parametrize("command", COMMANDS)
def test_the_help_names_only_options_the_command_takes(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    options = re.sub(r"-\n\s+", "-", text.split("options:", 1)[1])  # argparse breaks lines after a hyphen
    declared = set(re.findall(r"^\s+(?:-\w, )?(--[a-z][a-z0-9-]*)", options, re.M))
    declared |= set(re.findall(r"\[(--[a-z][a-z0-9-]*)", text)) | {"--help"}
    declared |= {"--no-" + d[2:] for d in declared} | {"--" + d[5:] for d in declared if d.startswith("--no-")}
    named = set(re.findall(r"(?<![\w.-])(--[a-z][a-z0-9-]*)(?![\w-]*\.)", options))
    assert named <= declared, sorted(named - declared)
