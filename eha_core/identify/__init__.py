"""
=================================================================================
Identification: least squares, transfer functions, grey box, black-box models
=================================================================================

Three routes from measured (or simulated) data to the actuator: the paper's
least squares in the time domain (eqs. 15-18), a continuous-time transfer
function of the closed loop and the physical parameters backed out of it
(eqs. 19-27), and grey-box estimation on the nonlinear model itself. Importing
this package imports none of its modules; most of them load scipy.

Least squares (time domain)
===========================

.. autosummary::

   lse.identify_lse              -- M, B, Af, d0, beta_e by filtered least squares (eq. 18) or IV
   lse.MeasuredData              -- the sampled t, x, v, p1, p2, u the estimators read
   lse_choices.checked_choices   -- the estimator (ls, iv) and intervals (newey-west, ewc), checked
   disturbance.parse_disturbance_model -- the disturbance model, constant or harmonic[:FREQ_HZ]
   lse_reading.read_all          -- what each estimate and its interval say, one word and one sentence

Transfer functions (frequency experiment)
=========================================

.. autosummary::

   tfest.tfest                   -- a continuous-time G(s) from sampled data, like MATLAB tfest
   tfest.oe_fit                  -- output-error fit only, from a given start model
   tfresult.TFEstimate           -- the estimate, its fit, covariance and diagnostics
   validate.compare              -- a model on data, MATLAB compare: its output and fit
   validate.simulate_tf          -- exact simulation of G(s) on a held or linear sampled input
   validate.residual_analysis    -- residual autocorrelation and cross-correlation with the input
   assessment.assess_residuals   -- a verdict on those correlations, in one sentence each
   spectral.data_frequency_response -- the data's own response: ETFE when periodic, spa otherwise
   uncertainty.pole_zero_regions -- poles and zeros with their confidence regions
   uncertainty.bode_band         -- a Bode diagram's confidence band
   step.step_response            -- a transfer function's step response and its figures
   step.nonlinear_step_response  -- the nonlinear closed loop's step response
   record.identify_record        -- G(s) from a student's own record, validated on its last part
   backout.backout               -- the plant P_hat (eq. 26) and its physical parameters (eq. 27)

Grey box (the nonlinear model)
==============================

.. autosummary::

   greybox.identify_greybox      -- any physical parameters by output error on the nonlinear model
   greybox.greybox_data          -- a simulated record for it, open or closed loop, with noise
   greybox_study.run_greybox_study -- the estimate over noise seeds against the Cramer-Rao bound
   holdout.validate_params       -- physical parameters judged on data they were not fitted to
   holdout.split_record          -- a record's last part held out of the estimation

Black-box models (the identification course)
============================================

.. autosummary::

   blackbox.IdData               -- sampled data of one or several experiments: split, merge, detrend
   blackbox.merge                -- several experiments as one estimation data set (MATLAB merge)
   blackbox.compare              -- any black-box model on data: simulation or k-step prediction, and its fit
   blackbox.criteria             -- loss, AIC, BIC and FPE of one-step prediction errors
   blackbox_experiment.BlackBoxExperiment -- the actuator recorded for it, closed or open loop
   polynomial.arx                -- ARX by least squares (MATLAB arx)
   polynomial.pem                -- ARX, ARMAX, OE, BJ by the prediction-error method (MATLAB pem)
   polynomial.PolynomialModel    -- such an estimate: A, B, C, D, F, covariance, fit
   subspace.n4sid                -- a state-space model by subspace identification (CVA or MOESP)
   subspace.ss_order_svd         -- the subspace singular values that show the number of states
   subspace.StateSpaceModel      -- such an estimate: A, B, C, D, K
   process.procest               -- process models: 1 or 2 poles, delay, integrator (MATLAB procest)
   process.ProcessModel          -- such an estimate, continuous-time values and its exact ZOH form
   selection.select_structure    -- orders and structures in a table: loss, AIC, BIC, validation fit
   selection.arx_grid            -- every ARX structure of a grid from one QR (MATLAB arxstruc)
   selection.residual_tests      -- a model's one-step residuals: white, independent of the input

Internals
=========

.. autosummary::

   _ctmodels                     -- transfer functions on sampled data: discretisation, simulation, fit
   _srivc                        -- tfest's stage 1, SRIVC iterations from several starts
   _oe_refine                    -- tfest's stage 2, output-error refinement and covariance
   _oe_criterion                 -- the output-error criterion both stages share
   _delay_search                 -- tfest's input-delay search
   _stats                        -- statistical constants shared by the estimators
"""
