"""Constants modules of the hand models in ``assets/`` (names and counts, checked by tests)."""
