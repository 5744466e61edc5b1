"""
=====================================================================================
Numerical core of the EHA teaching tool: model, simulation, identification (eha_core)
=====================================================================================

Importing this package stays light: it never imports panel, holoviews or bokeh,
and python-control / numba are imported only when a function needs them. It
re-exports nothing: import from the modules below (``from eha_core.simulate
import simulate``). Every refused argument is an :class:`eha_core.errors.FieldError`
(``NAME = VALUE is not allowed: WHAT``); SI units throughout. Results have a short
repr, estimates and runs ``to_pandas()``, the main ones ``plot()`` (docs/python.md).

The actuator
============

.. autosummary::

   params                        -- ActuatorParams: the physical parameters, checked; defaults the paper's
   param_table                   -- each parameter's unit, meaning, display and bound; the rules tying them
   model                         -- the nonlinear dynamics (eqs. 1-4): derivatives, rhs, bounds
   variants                      -- effects the paper leaves out (spool, leakage, Stribeck), off by default
   linear                        -- operating point and linearisation (eqs. 9-14, 20-24): P(s), H(s)
   linear.linearize              -- the LinearModel at an operating point: A, B, E, tf_coeffs, closed loop

Signals and simulation
======================

.. autosummary::

   signals                       -- Sine, Step, Square, Chirp, WhiteNoise, Sampled, sums; their text form
   signals.parse_signal          -- a signal from text such as ``sine:6:2+step:1``
   excitation.idinput            -- MATLAB-compatible excitations: rgs, rbs, prbs, sum of sines
   simulate.simulate             -- one open-loop run, nonlinear or linearised (compiled RK4)
   simulate.simulate_many        -- several open-loop runs on one grid, in parallel
   simulate.simulate_closed_loop -- the loop u = Kp (r - x) (eq. 22), sampled or continuous
   simulate.simulation_cost      -- steps, samples and peak memory of a run, before running it

The paper's experiments
=======================

.. autosummary::

   experiments.run_paper_cases   -- the open-loop cases of Figs. 2-7
   experiments.run_lse           -- simulate and identify by least squares (Tables 3-4)
   experiments.run_frequency_identification -- the closed-loop experiment and all that follows (Figs. 8-13)
   reproduction.reproduce        -- everything the paper shows, as one typed result
   study.run_study               -- one experiment over many noise seeds: spread, bias, coverage
   board                         -- candidate models of r -> x side by side: Bode, poles, step, fit
   plotting                      -- matplotlib figures behind the results' plot() (matplotlib optional)
   exercise.Exercise             -- a class exercise: each student's own actuator, hidden parameters
   identify                      -- identification: least squares, tfest, grey box (its own map)

Data, refusals, cancellation
============================

.. autosummary::

   data.read_data                -- columns of a CSV or .mat file in SI, with units in the header
   data.write_data               -- columns as the bytes of a CSV or .mat file
   errors                        -- FieldError, ComputationError, not_allowed: refusals as values
   cancel                        -- CancelToken and Cancelled: stopping long computations

Internals
=========

.. autosummary::

   _checks                       -- the argument checks and the one form of their messages
   _display                      -- the results' short reprs and tables: display units, ± standard errors
   _kernels                      -- the numba integrators (RK4, batches, sensitivities), loaded lazily
   _kernels_spool                -- the same for the six states of the valve's spool dynamics
"""
