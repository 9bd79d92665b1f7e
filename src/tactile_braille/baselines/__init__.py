"""Other libraries' agents on the benchmark, tuned by one protocol (docs/benchmark.md, "Baselines").

:mod:`.sb3`: Stable-Baselines3's DQN, SAC and TD3 with its ``HerReplayBuffer``, their search spaces,
an Optuna search on tuning seeds and the final runs on fresh seeds, each scored by
:func:`~tactile_braille.evaluation.evaluate_policy` into a results file that records its tuning.
"""
