"""What the test files share: the skip exception run.py counts, and message checks."""


class Skip(Exception):
    """A test that cannot run here: `requirement` is `torch`, `jax` or `cuda` (run.py's --require)."""

    def __init__(self, requirement, why):
        super().__init__(why)
        self.requirement = requirement
        self.why = why


def raises(exc_type, fn, *words):
    """Calls `fn`, which must raise `exc_type` with every word of `words` in its message
    (the op, the parameter, the values: §13 of the design). Returns the message."""
    try:
        fn()
    except exc_type as e:
        msg = str(e)
        missing = [w for w in words if w not in msg]
        if missing:
            raise AssertionError("%s's message lacks %r: %s" % (exc_type.__name__, missing, msg))
        return msg
    except Exception as e:  # the wrong type: say which
        raise AssertionError("expected %s, got %s: %s" % (exc_type.__name__, type(e).__name__, e))
    raise AssertionError("expected %s, nothing was raised" % exc_type.__name__)
