"""Importing fnnlib has no side effects on torch's threads; set_num_threads sets them."""

import subprocess
import sys

import pytest
import torch

from fnnlib.threads import set_num_threads


def test_import_leaves_threads_alone():
    code = "import torch; torch.set_num_threads(3); import fnnlib; print(torch.get_num_threads())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert int(done.stdout.strip()) == 3


def test_set_num_threads():
    n = torch.get_num_threads()
    try:
        set_num_threads(2)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(n)
    with pytest.raises(ValueError, match=">= 1"):
        set_num_threads(0)
