"""Suite-wide setup: the tests compute with one torch thread, as the notebooks do.

(Importing fnnlib no longer sets it; see fnnlib.set_num_threads.)
"""

import fnnlib


def pytest_configure(config):
    fnnlib.set_num_threads(1)
