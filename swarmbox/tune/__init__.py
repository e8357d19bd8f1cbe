"""Tuning an algorithm's parameters with Optuna, as a Hydra sweeper (``hydra/sweeper=tune``).

- :mod:`.space`: the search space from Hydra's sweep syntax (``interval``, ``range``, ``choice``, tags);
- :mod:`.objective`: the metrics optimised, their directions, a trial's score and the penalty rule;
- :mod:`.checks`: bad input refused before anything is written;
- :mod:`.callback`: the checks at the start, each run's objective values in its worker;
- :mod:`.study`: the ask-and-tell loop, its SQLite storage and resume;
- :mod:`.results`: the trials table, the best parameters, the held-out re-evaluation, Optuna's figures.

Usage and the reasons behind each rule: docs/tuning.md.
"""
