"""The page's sections (tabs and panels), registered in page order.

A new panel is one module here and one line below: it is then in the page, in
settings files, in the page's address, in the session report, in the guide (its
``guide_step``), in the work an exercise keeps for a student who joins again (its
``kept_work`` and ``restore_work``) and in the random walk of benchmarks/walker.py
(its ``form_css`` and ``run_buttons``).
"""

from ..session import SECTIONS
from .blackbox import BlackBoxPanel
from .board import ModelBoard
from .frequency import FrequencyPanel
from .greybox import GreyBoxPanel
from .least_squares import LeastSquaresPanel
from .parameters import ParametersTab
from .record import RecordPanel
from .simulation import SimulationTab
from .study import StudyPanel

__all__ = ["SECTIONS"]

SECTIONS.register(ParametersTab, tab="1. Parameters")
SECTIONS.register(SimulationTab, tab="2. Simulation")
SECTIONS.register(LeastSquaresPanel, tab="3. Identification", subtab="Time domain: least squares")
SECTIONS.register(FrequencyPanel, tab="3. Identification", subtab="Frequency domain: transfer function")
SECTIONS.register(RecordPanel, within="frequency")
SECTIONS.register(GreyBoxPanel, tab="3. Identification", subtab="Grey-box (nonlinear)")
SECTIONS.register(BlackBoxPanel, tab="3. Identification", subtab="Black-box models")
SECTIONS.register(ModelBoard, tab="3. Identification", subtab="Model board")
SECTIONS.register(StudyPanel, tab="3. Identification", subtab="Study over seeds")
