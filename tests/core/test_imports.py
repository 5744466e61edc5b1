import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["eha_core", "eha_core.params", "eha_core.simulate", "eha_core.linear",
                                    "eha_core.experiments", "eha_core.cli", "eha_core.signals", "eha_core.excitation"])
def test_core_import_stays_light(module):
    """Cold start: the core never imports the GUI stack, and defers control and numba."""
    code = (f"import sys, {module}; "
            "print(' '.join(m for m in ('panel', 'holoviews', 'bokeh', 'control', 'numba', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == ""
