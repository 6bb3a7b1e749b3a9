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


def jax_x64():
    """JAX with float64 on (the ops' f64 tests need it), or Skip("jax")."""
    try:
        import jax
    except ImportError:
        raise Skip("jax", "JAX not installed")
    jax.config.update("jax_enable_x64", True)
    return jax


def jax_device(jax, kind):
    """JAX's CPU device for `kind` "cpu", else its first GPU, or Skip("cuda")."""
    if kind == "cpu":
        return jax.devices("cpu")[0]
    try:
        gpus = jax.devices("gpu")
    except RuntimeError:
        gpus = []
    if not gpus:
        raise Skip("cuda", "no GPU backend in this jaxlib (jax.devices('gpu') is empty)")
    return gpus[0]
