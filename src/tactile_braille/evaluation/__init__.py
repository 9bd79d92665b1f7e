"""The paper's evaluation protocol (typing sequences of keys), and scoring any agent on it.

``evaluate_policy(policy, task)`` types the paper's sequences with any
callable from observations to actions and returns a :class:`TypingReport`
with a protocol fingerprint; :mod:`~tactile_braille.evaluation.results`
writes it as a results file, :mod:`~tactile_braille.evaluation.leaderboard`
ranks results files.
"""

from tactile_braille.evaluation.protocol import (
    SENTENCES,
    TypingResult,
    paper_sequences,
    text_keys,
    type_sequences,
)
from tactile_braille.evaluation.scoring import PolicyError, TypingReport, evaluate_policy, touch_optimum

__all__ = [
    "SENTENCES", "PolicyError", "TypingReport", "TypingResult", "evaluate_policy", "paper_sequences",
    "text_keys", "touch_optimum", "type_sequences",
]  # fmt: skip
