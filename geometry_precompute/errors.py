"""The one error type for bad input (SPEC section 13).

Every loader and public function raises :class:`InputError` for input it
rejects. The message always names the source (a file, or "<settings>" /
"<argument>" for values that came from elsewhere), the field and the rule,
so the command line can print it as one line and exit non-zero.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: ``source: field: rule``."""

    def __init__(self, source: str, field: str, rule: str):
        self.source = str(source)
        self.field = field
        self.rule = rule
        super().__init__(f"{self.source}: {field}: {rule}")

    def __reduce__(self):
        # Raised in a worker process, it travels back to the command whole.
        return (type(self), (self.source, self.field, self.rule))
