"""The paper's evaluation protocol: typing sequences of keys without a reset between them."""

from tactile_braille.evaluation.protocol import (
    SENTENCES,
    TypingResult,
    evaluate_typing,
    paper_sequences,
    text_keys,
    type_sequences,
)

__all__ = ["SENTENCES", "TypingResult", "evaluate_typing", "paper_sequences", "text_keys", "type_sequences"]
