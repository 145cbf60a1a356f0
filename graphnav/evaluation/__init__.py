"""Scoring and reporting: metrics (:mod:`.metrics`, evo-checked), one result scored
(:mod:`.evaluate`), every estimator on one log (:mod:`.comparison`), the report and its figures
(:mod:`.report`, :mod:`.plots`), Monte Carlo trials (:mod:`.monte_carlo_trials`) and the sweep runner
(:mod:`.sweep`)."""
