"""Signal processing (spec chapters 6, 7 and 14): gravity calibration of the handle (:mod:`.calibration`,
chapter 6), common resampling and filtering (:mod:`.preprocessing`, §7.1–7.4), the calibrated handle signals
(:mod:`.signals`, §7.5), the force plate and a C3D platform's wrench (:mod:`.force_plate`, chapter 14;
:mod:`.platform_wrench`, §5.6.1), device kinematics (:mod:`.kinematics`, §8.2), banks of linear filters
(:mod:`.filter_bank`, §11.3), the compiled loops behind them (:mod:`.compiled_loops`) and the per-run cache
they share (:mod:`.caching`, §15.4). The package imports none of its modules.
"""
