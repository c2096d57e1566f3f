"""The two kinds of fault a user can cause or meet, each one line.

- :class:`InputError`: bad input (reference/errors). Every loader and public function
  raises it for input it rejects; the message names the source (a file, or
  "<settings>" / "<arguments>" for values that came from elsewhere), the field and
  the rule. The command line prints it and exits with status 2.
- :class:`HostError`: a fault of the machine rather than of the input: a full disk,
  a read-only or unreadable path, a folder where a file belongs. The message names
  the path, what could not be done and the operating system's reason. The command
  line prints it and exits with status 1.

Both messages are one line whatever they quote: control characters (a newline in an
id, say) are shown escaped, and very long quotes are cut (:func:`one_line`).
"""

from __future__ import annotations

import os
import reprlib

MAX_LINE = 600  # characters of one message; longer quotes are cut with "..."

_SHORT = reprlib.Repr()
_SHORT.maxstring = 80
_SHORT.maxother = 80
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = 6
_SHORT.maxlevel = 3


def shown(value) -> str:
    """A value as an error message quotes it: short, and safe for any nesting."""
    return _SHORT.repr(value)


def one_line(text: str, limit: int = MAX_LINE) -> str:
    """``text`` with every control character escaped (``\\n``, ``\\x1b``), cut to
    ``limit`` characters."""
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))
    return out if len(out) <= limit else out[:limit - 3] + "..."


class InputError(ValueError):
    """Bad input: ``source: field: rule``, printed as one line. ``source`` names the
    file (or ``<arguments>``, ``<--set>``), ``field`` the field (``objects[a].radius``)
    and ``rule`` what was expected and what was found. Raised by every loader and
    public function before anything is written; a ``ValueError``."""

    def __init__(self, source: str | os.PathLike, field: str, rule: str):
        self.source = one_line(str(source), 200)
        self.field = one_line(field, 200)
        self.rule = one_line(rule)
        super().__init__(f"{self.source}: {self.field}: {self.rule}")

    def __reduce__(self):
        # Raised in a worker process, it travels back to the command whole.
        return (type(self), (self.source, self.field, self.rule))


class HostError(OSError):
    """The machine refused: ``path: cannot <action> (<reason>)``: a full disk, a
    folder without write permission, a cache that cannot be created. The command line
    prints it as one line and exits with status 1, as it does an :class:`InputError`;
    an ``OSError``, so ``except OSError`` catches it.

    Example::

        >>> from geometry_precompute import HostError
        >>> str(HostError("/data/out", "write", "No space left on device"))
        '/data/out: cannot write (No space left on device)'
    """

    def __init__(self, path, action: str, reason: str):
        self.path = one_line(str(path), 300)
        self.action = action
        self.reason = one_line(reason, 200)
        super().__init__(f"{self.path}: cannot {action} ({self.reason})")

    def __str__(self) -> str:
        return self.args[0]

    def __reduce__(self):
        return (type(self), (self.path, self.action, self.reason))

    @classmethod
    def of(cls, error: OSError, path, action: str) -> HostError:
        """The :class:`HostError` of an ``OSError`` met while doing ``action`` on
        ``path`` (its own file name wins where it has one)."""
        if isinstance(error, HostError):
            return error
        where = error.filename if error.filename is not None else path
        return cls(where, action, error.strerror or type(error).__name__)


class SceneWarning(UserWarning):
    """Legal but probably unintended input: scene content, or a value that looks like a
    unit mistake (degrees for radians, centimetres for metres). The command line shows
    each as one ``warning:`` line; the input is used as given."""


def did_you_mean(name: str, choices) -> str:
    """``"; did you mean X?"`` for the choice closest to a misspelt ``name``
    (``difflib``'s ratio of at least 0.6), else ``""``.

    >>> did_you_mean("v_mx", ["v_max", "dt", "seed"])
    '; did you mean v_max?'
    >>> did_you_mean("colour", ["v_max", "dt"])
    ''
    """
    import difflib  # here: only on an error

    close = difflib.get_close_matches(str(name), [str(c) for c in choices], n=1)
    return f"; did you mean {close[0]}?" if close else ""


def unknown_field(allowed, name: str | None = None) -> str:
    """The rule of an unknown key: the keys its table allows, by name, or that the
    table takes none (never an empty list); with the key ``name``, the allowed one it
    most likely meant.

    >>> unknown_field({"radius", "height"})
    'unknown field (allowed: height, radius)'
    >>> unknown_field({"radius", "height"}, "hieght")
    'unknown field; did you mean height? (allowed: height, radius)'
    >>> unknown_field(set())
    'unknown field (this table takes no fields)'
    """
    names = sorted(allowed)
    if not names:
        return "unknown field (this table takes no fields)"
    hint = did_you_mean(name, names) if name is not None else ""
    return f"unknown field{hint} (allowed: {', '.join(names)})"

