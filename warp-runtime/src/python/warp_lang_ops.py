"""warp-lang's op helper, embedded in every extension module that registers ops
(``wp::python::Ops``) and installed as ``<module>._warp_lang``.

Each op of the module is an :class:`Op` wrapping the native object (``NativeOp``): the
framework calls live here, the checks and launches in Rust. The helper allocates every
buffer (outputs, gradients) with the caller's framework; the native side only launches on
them. torch is imported inside the methods that use it, never at import time.
"""

import threading

_ARRAYS = ("input", "output", "scratch")


class Op:
    """A warp-lang op. Call it with the kernel's parameters minus its outputs, in kernel order
    (each may be given by keyword): arrays as tensors of the scalar dtype with the element's
    components as trailing axes, scalars as Python numbers, vector, quaternion and matrix
    values as sequences of them (nested as the component axes, or flat; a NumPy array).

    - ``op.numpy(*args)``: NumPy arrays on the CPU; returns new arrays.
    - ``op.vjp_numpy(primals, cotangents)``: the input gradients (CPU).
    - ``op.torch(*args)``: a ``torch.autograd.Function`` (CPU or CUDA tensors; CUDA work runs
      on torch's current stream of the tensors' device).
    - ``op(*args)``: dispatches on the first array: torch tensors to ``torch``, anything else
      to the DLPack path (NumPy's ``numpy``).
    - ``op.spec``: the parameters as plain data.
    """

    def __init__(self, native):
        self._native = native
        self.spec = native.spec
        self.name = self.spec["name"]
        self.kind = self.spec["kind"]
        params = self.spec["params"]
        self._params = params
        # The call's parameters: inputs and scalars, in kernel order.
        self._call = [p for p in params if p["role"] in ("input", "scalar")]
        self._outputs = [p for p in params if p["role"] == "output"]
        self._lock = threading.Lock()
        self._torch_fn = None
        self._torch_op = None
        self._jax_fns = {}
        self._alloc_cache = {}
        self._jax_prepared = False
        self.__doc__ = "%s\n\n%s" % (self.signature(), Op.__doc__)
        import sys

        if "torch" in sys.modules:
            # torch is loaded already: register the op with torch.library now, so that its
            # first torch_op call may be inside torch.compile.
            try:
                self._torch_library()
            except Exception:  # an old torch without custom_op: torch_op says so when called
                pass

    # ---- signature and arguments

    def signature(self):
        """``name(x: Array<DVec3, 1> (float64, trailing axes [3]), k: float64) -> (e: ...)``."""

        def one(p):
            return "%s: %s" % (p["name"], p["describe"])

        return "%s(%s) -> (%s)" % (
            self.name,
            ", ".join(one(p) for p in self._call),
            ", ".join(one(p) for p in self._outputs),
        )

    def __repr__(self):
        return "<warp_lang %s op %s>" % (self.kind, self.signature())

    def _bind(self, args, kwargs):
        """The call's values by parameter name, with Python's own TypeError texts plus the
        op's signature."""
        names = [p["name"] for p in self._call]
        if len(args) > len(names):
            raise TypeError(
                "%s takes %d arguments (%d given): %s"
                % (self.name, len(names), len(args), self.signature())
            )
        bound = dict(zip(names, args))
        for k, v in kwargs.items():
            if k not in names:
                raise TypeError(
                    "%s got an unexpected keyword argument '%s': %s" % (self.name, k, self.signature())
                )
            if k in bound:
                raise TypeError(
                    "%s got multiple values for argument '%s': %s" % (self.name, k, self.signature())
                )
            bound[k] = v
        missing = [n for n in names if n not in bound]
        if missing:
            raise TypeError(
                "%s missing %d required argument%s: %s; %s"
                % (
                    self.name,
                    len(missing),
                    "" if len(missing) == 1 else "s",
                    ", ".join("'%s'" % m for m in missing),
                    self.signature(),
                )
            )
        for p in self._call:
            if p["role"] == "scalar" and p["element"]:
                bound[p["name"]] = _components(bound[p["name"]])
        return bound

    def _allocs(self, bound, shape_of):
        """``[(param, full shape)]`` of each output and scratch array for the call (the native
        shape rules over the inputs' shapes and the scalars), and whether the call launches
        anything (a launch over no element is an error in warp-lang: such a call is skipped,
        its outputs and gradients staying zero)."""
        shapes, values = [], []
        for p in self._params:
            if p["role"] == "input":
                shapes.append(tuple(int(d) for d in shape_of(bound[p["name"]], p)))
                values.append(None)
            elif p["role"] == "scalar":
                shapes.append(None)
                values.append(bound[p["name"]])
            else:
                shapes.append(None)
                values.append(None)
        # The rules are pure functions of the shapes and scalars: a training loop's calls,
        # which repeat them, skip the native call (a cache of the last few; the key carries
        # each scalar's type, so that 1 and 1.0 are checked apart).
        try:
            key = (tuple(shapes), tuple((type(v), v) for v in values))
            hit = self._alloc_cache.get(key)
        except TypeError:  # an unhashable scalar: the native side names the error
            key, hit = None, None
        if hit is not None:
            return hit
        dims, leading = self._native._shapes(shapes, values)
        made = [p for p in self._params if p["role"] in ("output", "scratch")]
        out = [(p, tuple(s) + tuple(p["element"])) for p, s in zip(made, leading)], 0 not in dims
        if key is not None:
            if len(self._alloc_cache) >= 64:
                self._alloc_cache.clear()
            self._alloc_cache[key] = out
        return out

    def _args(self, bound, made):
        """The native call's list: one entry per parameter."""
        return [made[p["name"]] if p["role"] in ("output", "scratch") else bound[p["name"]] for p in self._params]

    def _result(self, made):
        outs = tuple(made[p["name"]] for p in self._outputs)
        return outs[0] if len(outs) == 1 else outs

    # ---- dispatch

    def __call__(self, *args, **kwargs):
        bound = self._bind(args, kwargs)
        first = next((bound[p["name"]] for p in self._call if p["role"] == "input"), None)
        mod = type(first).__module__ or ""
        if mod.split(".")[0] == "torch":
            return self.torch(*args, **kwargs)
        if mod.split(".")[0] in ("jax", "jaxlib"):
            return self.jax(*args, **kwargs)
        return self.numpy(*args, **kwargs)

    # ---- NumPy (CPU)

    def _numpy_inputs(self, bound):
        import numpy as np

        for k, p in enumerate(self._call):
            if p["role"] == "input" and not isinstance(bound[p["name"]], np.ndarray):
                raise TypeError(
                    "%s: argument '%s' (%d): a %s; the kernel takes %s (a NumPy array)"
                    % (self.name, p["name"], k, type(bound[p["name"]]).__name__, p["describe"])
                )

    def numpy(self, *args, **kwargs):
        """The forward on NumPy arrays (CPU): new arrays, one per output (a tuple when the op
        has several)."""
        import numpy as np

        bound = self._bind(args, kwargs)
        self._numpy_inputs(bound)
        allocs, launches = self._allocs(bound, _shape)
        made = {p["name"]: np.zeros(shape, dtype=_np_dtype(np, p)) for p, shape in allocs}
        if launches:
            self._native._forward(None, self._args(bound, made))
        return self._result(made)

    def vjp_numpy(self, primals, cotangents, **kwargs):
        """The gradient of ``sum(cotangent * output)`` with respect to each input array, on
        NumPy arrays (CPU): ``primals`` are the call's arguments (a tuple in call order; scalars
        may also be keywords), ``cotangents`` one array per output (a bare array for one output).
        Returns a tuple with one entry per input array, in call order: its gradient, or None
        for an integer input."""
        import numpy as np

        if not isinstance(primals, (tuple, list)):
            primals = (primals,)
        bound = self._bind(tuple(primals), kwargs)
        self._numpy_inputs(bound)
        # Each gradient shares its input's layout: C order for both.
        for p in self._call:
            if p["role"] == "input":
                bound[p["name"]] = np.ascontiguousarray(bound[p["name"]])
        if not isinstance(cotangents, (tuple, list)):
            cotangents = (cotangents,)
        if len(cotangents) != len(self._outputs):
            raise TypeError(
                "%s: %d cotangents given; the op has %d outputs (%s)"
                % (self.name, len(cotangents), len(self._outputs), ", ".join(p["name"] for p in self._outputs))
            )
        allocs, launches = self._allocs(bound, _shape)
        made = {p["name"]: np.zeros(shape, dtype=_np_dtype(np, p)) for p, shape in allocs}
        if launches and self.kind == "kernel":
            # The adjoint reads the forward's outputs.
            self._native._forward(None, self._args(bound, made))
        grads = [None] * len(self._params)
        by_name = {p["name"]: k for k, p in enumerate(self._params)}
        for p, c in zip(self._outputs, cotangents):
            shape = made[p["name"]].shape
            c = np.asarray(c)
            if c.shape != shape:
                raise ValueError(
                    "%s: the cotangent of output '%s' has shape %s; the output's is %s"
                    % (self.name, p["name"], c.shape, shape)
                )
            if p["differentiable"]:
                # A copy: the adjoint reads and clears it.
                grads[by_name[p["name"]]] = np.array(c, dtype=_np_dtype(np, p), order="C", copy=True)
        out = []
        for p in self._call:
            if p["role"] != "input":
                continue
            if p["differentiable"]:
                g = np.zeros(bound[p["name"]].shape, dtype=_np_dtype(np, p))
                grads[by_name[p["name"]]] = g
                out.append(g)
            else:
                out.append(None)
        if launches:
            self._native._backward(None, self._args(bound, made), grads)
        return tuple(out)

    # ---- torch

    def torch(self, *args, **kwargs):
        """The op as a ``torch.autograd.Function`` on CPU or CUDA tensors (all on one device):
        the outputs are new tensors; their gradients flow back through the kernel's adjoint
        (a kernel op) or a replay of the body under a tape (a computation op)."""
        bound = self._bind(args, kwargs)
        fn = self._torch_function()
        return fn.apply(*[bound[p["name"]] for p in self._call])

    def torch_op(self, *args, **kwargs):
        """The op as a ``torch.library.custom_op`` (``torch.ops.warp_lang_<module>.<name>``):
        the same computation as :meth:`torch`, but ``torch.compile`` keeps it in its graph as
        an opaque call (a fake implementation gives the outputs' shapes; the backward is a
        second custom op), so a compiled model need not break its graph around it."""
        bound = self._bind(args, kwargs)
        fn = self._torch_op
        if fn is None:
            # Registering the custom ops is Python that torch.compile cannot trace: it happens
            # at the first call, which must be outside a compiled function (or torch was
            # imported before this module, and it happened then).
            fn = self._torch_library()
        return fn(*[bound[p["name"]] for p in self._call])

    def _torch_library(self):
        with self._lock:
            if self._torch_op is None:
                self._torch_op = _make_torch_op(self)
            return self._torch_op

    def _torch_function(self):
        with self._lock:
            if self._torch_fn is None:
                self._torch_fn = _make_torch_function(self)
            return self._torch_fn

    # ---- JAX

    def jax(self, *args, **kwargs):
        """The op on JAX arrays (CPU or GPU), through XLA's FFI: usable under ``jax.jit``,
        differentiable in reverse mode (``jax.grad``, ``jax.vjp``: a ``custom_vjp`` whose
        backward is the kernel's adjoint, or a replay of the body under a tape) and batched by
        ``jax.vmap`` over leading axes. Scalars are static: Python or NumPy numbers, not traced
        values (pass a value to differentiate as an array input)."""
        bound = self._bind(args, kwargs)
        scalars = []
        for k, p in enumerate(self._call):
            if p["role"] != "scalar":
                continue
            v = bound[p["name"]]
            if not _is_static(p, v):
                raise TypeError(
                    "%s: scalar '%s' (%d) is a %s; an op's scalars are static (a Python or NumPy "
                    "number, or for a vector or matrix a sequence of them or a NumPy array), not "
                    "traced values: pass a value to differentiate or to vary under jit as an array "
                    "input" % (self.name, p["name"], k, type(v).__name__)
                )
            scalars.append((p["name"], v))
        key = tuple((n, type(v).__name__, v) for n, v in scalars)
        with self._lock:
            fn = self._jax_fns.get(key)
            if fn is None:
                fn = self._jax_fns[key] = _make_jax_function(self, dict(scalars))
        return fn(*[bound[p["name"]] for p in self._call if p["role"] == "input"])

    def _trace_addresses(self):
        """``{parameter: address}`` of every buffer the last call launched on (``grad:<name>``
        for gradients): equal to the tensors' ``data_ptr()`` when nothing was copied."""
        return dict(self._native._trace_addresses())


def _shape(a, p):
    return a.shape


def _np_dtype(np, p):
    if p["dtype"] == "bfloat16":
        raise TypeError("op parameter '%s' is bfloat16, which NumPy has no dtype for" % p["name"])
    return np.dtype(p["dtype"])


def _torch_device_check(op, bound):
    import torch

    first = None
    for k, p in enumerate(op._call):
        if p["role"] != "input":
            continue
        t = bound[p["name"]]
        if not isinstance(t, torch.Tensor):
            raise TypeError(
                "%s: argument '%s' (%d): a %s; the kernel takes %s (a torch.Tensor)"
                % (op.name, p["name"], k, type(t).__name__, p["describe"])
            )
        if first is None:
            first = (p["name"], t.device)
        elif t.device != first[1]:
            raise ValueError("%s: '%s' is on %s, '%s' on %s" % (op.name, first[0], first[1], p["name"], t.device))
    return first[1]


def _torch_stream(torch, dev):
    return torch.cuda.current_stream(dev).cuda_stream if dev.type == "cuda" else None


def _torch_dtype(torch, p):
    return getattr(torch, p["dtype"])


def _torch_fresh(op, torch, bound, dev):
    """The call's outputs and scratch as new tensors, and whether the call launches."""
    allocs, launches = op._allocs(bound, lambda t, p: t.shape)
    made = {
        p["name"]: (torch.zeros if p["zeroed"] or p["role"] == "scratch" else torch.empty)(
            shape, dtype=_torch_dtype(torch, p), device=dev
        )
        for p, shape in allocs
    }
    return made, launches


def _torch_forward(op, torch, bound):
    """The forward on torch tensors: ``bound`` holds the call's values by name (its input
    tensors are replaced by detached views: DLPack refuses tensors that require grad). Returns
    the outputs in order and the device."""
    dev = _torch_device_check(op, bound)
    for p in op._call:
        if p["role"] == "input":
            bound[p["name"]] = bound[p["name"]].detach()
    made, launches = _torch_fresh(op, torch, bound, dev)
    if launches:
        op._native._forward(_torch_stream(torch, dev), op._args(bound, made))
    return [made[p["name"]] for p in op._outputs], dev


def _torch_backward(op, torch, bound, dev, outs, grad_outs, wanted):
    """The backward on torch tensors: ``bound`` the call's values by name (detached inputs),
    ``outs`` the forward's outputs (a kernel op's adjoint reads them; ignored for a
    computation op, whose body is replayed on fresh ones), ``grad_outs`` one gradient (or
    None) per output, ``wanted`` one flag per call parameter. Returns one entry per call
    parameter: the input's gradient, or None."""
    by_name = {p["name"]: k for k, p in enumerate(op._params)}
    if op.kind == "kernel":
        made = {p["name"]: t for p, t in zip(op._outputs, outs)}
        _, launches = op._allocs(bound, lambda t, p: t.shape)
    else:
        made, launches = _torch_fresh(op, torch, bound, dev)
    grads = [None] * len(op._params)
    for p, g in zip(op._outputs, grad_outs):
        if not p["differentiable"]:
            continue
        if g is None:
            g = torch.zeros_like(made[p["name"]])
        # The adjoint reads and clears it; a contiguous copy (for `sum()` also the
        # materialisation of an expanded tensor of ones).
        grads[by_name[p["name"]]] = g.detach().to(_torch_dtype(torch, p)).clone(memory_format=torch.contiguous_format)
    result = []
    for p, want in zip(op._call, wanted):
        if p["role"] == "input" and want and p["differentiable"]:
            x = bound[p["name"]]
            # The gradient shares its array's layout (strides), whatever the view.
            g = torch.empty_strided(x.size(), x.stride(), dtype=x.dtype, device=x.device).zero_()
            grads[by_name[p["name"]]] = g
            result.append(g)
        else:
            result.append(None)
    if launches and any(r is not None for r in result):
        op._native._backward(_torch_stream(torch, dev), op._args(bound, made), grads)
    return result


def _make_torch_function(op):
    import torch

    call_names = [p["name"] for p in op._call]
    inputs = [p for p in op._call if p["role"] == "input"]

    class Function(torch.autograd.Function):
        @staticmethod
        def forward(ctx, *flat):
            bound = dict(zip(call_names, flat))
            outs, dev = _torch_forward(op, torch, bound)
            ctx.op_bound = {n: v for n, v in bound.items() if n not in {p["name"] for p in inputs}}
            ctx.op_device = dev
            arrays = [bound[p["name"]] for p in inputs]
            ctx.save_for_backward(*arrays, *(outs if op.kind == "kernel" else []))
            nondiff = [o for p, o in zip(op._outputs, outs) if not p["differentiable"]]
            if nondiff:
                ctx.mark_non_differentiable(*nondiff)
            return outs[0] if len(outs) == 1 else tuple(outs)

        @staticmethod
        @torch.autograd.function.once_differentiable
        def backward(ctx, *grad_outs):
            # Saved outputs come back attached to the graph, and DLPack (torch's CPU export)
            # refuses a tensor that requires grad: the op reads values only.
            saved = [t.detach() for t in ctx.saved_tensors]
            bound = dict(ctx.op_bound)
            for p, t in zip(inputs, saved):
                bound[p["name"]] = t
            grads = _torch_backward(
                op, torch, bound, ctx.op_device, saved[len(inputs) :], grad_outs, ctx.needs_input_grad
            )
            return tuple(grads)

    Function.__name__ = Function.__qualname__ = "_TorchFn_%s" % op.name
    return Function


def _schema_type(p):
    if p["role"] == "input":
        return "Tensor"
    if p["dtype"] == "bool":
        one = "bool"
    else:
        one = "float" if "float" in p["dtype"] else "int"
    # A vector's, quaternion's or matrix's components: a flat list.
    return one + "[]" if p["element"] else one


def _make_torch_op(op):
    """The op as a ``torch.library.custom_op`` (``<namespace>::<name>``), with a fake
    implementation (the shape rules) and autograd through a second custom op for the
    backward, so that ``torch.compile`` keeps it in its graph as an opaque call."""
    import torch

    ns = "warp_lang_" + "".join(c if c.isalnum() else "_" for c in _FFI_PREFIX.split(".", 1)[1])
    call_names = [p["name"] for p in op._call]
    in_params = [p for p in op._call if p["role"] == "input"]
    diff_in = [p for p in in_params if p["differentiable"]]
    diff_out = [p for p in op._outputs if p["differentiable"]]
    kept = op._outputs if op.kind == "kernel" else []

    def returns(n):
        return "Tensor" if n == 1 else "(%s)" % ", ".join(["Tensor"] * n)

    args = ", ".join("%s %s" % (_schema_type(p), p["name"]) for p in op._call)
    fwd_schema = "(%s) -> %s" % (args, returns(len(op._outputs)))

    def result(xs):
        return xs[0] if len(xs) == 1 else tuple(xs)

    def fwd_impl(*flat):
        outs, _ = _torch_forward(op, torch, dict(zip(call_names, flat)))
        return result(outs)

    def fake_outs(flat):
        bound = dict(zip(call_names, flat))
        dev = next(bound[p["name"]].device for p in in_params)
        allocs, _ = op._allocs(bound, lambda t, p: t.shape)
        made = {p["name"]: torch.empty(shape, dtype=_torch_dtype(torch, p), device=dev) for p, shape in allocs}
        return [made[p["name"]] for p in op._outputs]

    fwd = torch.library.custom_op("%s::%s" % (ns, op.name), mutates_args=(), schema=fwd_schema)(fwd_impl)
    fwd.register_fake(lambda *flat: result(fake_outs(flat)))
    if not diff_in:
        return fwd

    bwd_args = args
    if kept:
        bwd_args += ", " + ", ".join("Tensor out_%s" % p["name"] for p in kept)
    bwd_args += ", " + ", ".join("Tensor ct_%s" % p["name"] for p in diff_out) if diff_out else ""
    bwd_schema = "(%s) -> %s" % (bwd_args, returns(len(diff_in)))
    n_call, n_kept = len(call_names), len(kept)

    def bwd_impl(*flat):
        bound = dict(zip(call_names, flat[:n_call]))
        dev = _torch_device_check(op, bound)
        for p in in_params:
            bound[p["name"]] = bound[p["name"]].detach()
        outs = [t.detach() for t in flat[n_call : n_call + n_kept]]
        cts = dict(zip((p["name"] for p in diff_out), flat[n_call + n_kept :]))
        grad_outs = [cts.get(p["name"]) for p in op._outputs]
        wanted = [p["role"] == "input" and p["differentiable"] for p in op._call]
        grads = _torch_backward(op, torch, bound, dev, outs, grad_outs, wanted)
        return result([g for g, p in zip(grads, op._call) if p["role"] == "input" and p["differentiable"]])

    bwd = torch.library.custom_op("%s::%s_bwd" % (ns, op.name), mutates_args=(), schema=bwd_schema)(bwd_impl)
    bwd.register_fake(lambda *flat: result([torch.empty_like(flat[call_names.index(p["name"])]) for p in diff_in]))

    def setup_context(ctx, inputs, output):
        outs = list(output) if isinstance(output, tuple) else [output]
        ctx.scalars = {p["name"]: v for p, v in zip(op._call, inputs) if p["role"] != "input"}
        tensors = [v for p, v in zip(op._call, inputs) if p["role"] == "input"]
        ctx.save_for_backward(*tensors, *(outs[op._outputs.index(p)] for p in kept))

    def backward(ctx, *grads):
        ct = [g for p, g in zip(op._outputs, grads) if p["differentiable"]]
        saved = list(ctx.saved_tensors)
        tensors = iter(saved[: len(in_params)])
        flat = [next(tensors) if p["role"] == "input" else ctx.scalars[p["name"]] for p in op._call]
        got = bwd(*flat, *saved[len(in_params) :], *ct)
        got = list(got) if isinstance(got, tuple) else [got]
        by = dict(zip((p["name"] for p in diff_in), got))
        return tuple(by.get(p["name"]) if p["role"] == "input" else None for p in op._call)

    fwd.register_autograd(backward, setup_context=setup_context)
    return fwd


# ---- JAX: the op as XLA FFI calls (`ops/xla_ffi.rs` holds the handlers)

# Set by `Ops::new`: the targets' prefix (`warp_lang.<module>`) and `[(target, platform,
# capsule)]`, the module's eight handlers.
_FFI_PREFIX = None
_FFI_HANDLERS = ()
_FFI_LOCK = threading.Lock()
_FFI_REGISTERED = False


def _is_number(v):
    import numbers

    import numpy as np

    return isinstance(v, (numbers.Number, np.number, np.bool_)) and not hasattr(v, "aval")


def _is_static(p, v):
    """Whether `v` (bound, so a vector's components are a tuple) is a static value of `p`."""
    if p["element"]:
        return isinstance(v, tuple) and all(_is_number(x) for x in v)
    return _is_number(v)


def _components(v):
    """A vector's, quaternion's or matrix's value as the flat tuple of its components (row-major
    over nested sequences; a NumPy array or a tensor through ``tolist``); anything else as it
    is, for the native side to name."""
    if hasattr(v, "tolist") and hasattr(v, "ndim") and not hasattr(v, "aval"):
        v = v.tolist()
    if not isinstance(v, (list, tuple)):
        return v
    out = []
    for x in v:
        x = _components(x)
        if isinstance(x, tuple):
            out.extend(x)
        else:
            out.append(x)
    return tuple(out)


def _jax_register(jax):
    """Registers the module's handlers with XLA, once per process."""
    global _FFI_REGISTERED
    with _FFI_LOCK:
        if _FFI_REGISTERED:
            return
        for target, platform, capsule in _FFI_HANDLERS:
            name = "%s.%s" % (_FFI_PREFIX, target)
            try:
                jax.ffi.register_ffi_target(name, capsule, platform=platform, api_version=1)
            except Exception:
                # A jaxlib without that platform's plugin (CUDA on a CPU-only install): the
                # target is never called there.
                if platform == "cpu":
                    raise
        _FFI_REGISTERED = True


def _jax_prepare(op, jax):
    """Loads the op's kernels on every local GPU before the first call, so that no call
    compiles or allocates inside XLA's command-buffer capture."""
    with op._lock:
        if op._jax_prepared:
            return
        try:
            gpus = jax.local_devices(backend="gpu")
        except RuntimeError:
            gpus = []
        for d in gpus:
            op._native._prepare(int(getattr(d, "local_hardware_id", None) or d.id))
        op._jax_prepared = True


def _jax_dtype(jnp, p):
    return jnp.dtype(p["dtype"])


def _make_jax_function(op, scalars):
    """The op's ``custom_vjp`` function of its array inputs for one set of scalar values."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    _jax_register(jax)
    params = op._params
    inputs = [p for p in op._call if p["role"] == "input"]
    pos = {p["name"]: k for k, p in enumerate(params)}
    wide = [p for p in params if p["dtype"] in ("float64", "int64", "uint64")]
    if wide and not jax.config.jax_enable_x64:
        raise TypeError(
            "%s: parameter '%s' is %s, which JAX holds only with jax_enable_x64 on "
            "(jax.config.update('jax_enable_x64', True))" % (op.name, wide[0]["name"], wide[0]["dtype"])
        )
    attrs = {"warp_op": np.int64(op._native.id)}
    for p in params:
        if p["role"] == "scalar":
            dt = np.dtype(_jax_dtype(jnp, p))
            v = scalars[p["name"]]
            # A vector's or matrix's components: an array attribute, row-major.
            attrs[p["name"]] = np.asarray(v, dtype=dt).ravel() if p["element"] else dt.type(v)
    mode = "graph" if op.kind == "kernel" else "eager"
    target = {d: "%s.%s.%s" % (_FFI_PREFIX, d, mode) for d in ("fwd", "bwd")}
    layout = {d: op._native._layout(d) for d in ("fwd", "bwd")}
    outputs = op._outputs

    def check(arrays):
        for k, (p, a) in enumerate(zip(inputs, arrays)):
            want = _jax_dtype(jnp, p)
            dt = getattr(a, "dtype", None)
            if dt != want:
                raise TypeError(
                    "%s: argument '%s' (%d) has dtype %s; the kernel takes %s (%s)"
                    % (op.name, p["name"], k, dt, p["describe"], want)
                )

    def allocs(arrays):
        bound = dict(zip((p["name"] for p in inputs), arrays))
        bound.update(scalars)
        made, launches = op._allocs(bound, lambda a, p: a.shape)
        return {p["name"]: jax.ShapeDtypeStruct(shape, _jax_dtype(jnp, p)) for p, shape in made}, launches

    def forward(arrays):
        check(arrays)
        _jax_prepare(op, jax)
        made, launches = allocs(arrays)
        by_pos = {pos[p["name"]]: a for p, a in zip(inputs, arrays)}
        if launches:
            ops_in, res = layout["fwd"]
            outs = jax.ffi.ffi_call(target["fwd"], [made[params[k]["name"]] for _, k in res], vmap_method="expand_dims")(
                *[by_pos[k] for _, k in ops_in], **attrs
            )
            vals = {params[k]["name"]: o for (_, k), o in zip(res, outs)}
        else:
            vals = {n: jnp.zeros(t.shape, t.dtype) for n, t in made.items()}
        return tuple(vals[p["name"]] for p in outputs), made, launches

    def result(outs):
        return outs[0] if len(outs) == 1 else outs

    @jax.custom_vjp
    def f(*arrays):
        return result(forward(arrays)[0])

    def f_fwd(*arrays):
        outs, _, _ = forward(arrays)
        return result(outs), (arrays, outs if op.kind == "kernel" else ())

    def f_bwd(res, cts):
        arrays, outs = res
        if len(outputs) == 1:
            cts = (cts,)
        made, launches = allocs(arrays)
        value = {pos[p["name"]]: a for p, a in zip(inputs, arrays)}
        value.update({pos[p["name"]]: o for p, o in zip(outputs, outs)})
        ct = {pos[p["name"]]: c for p, c in zip(outputs, cts)}
        grads = {}
        if launches:
            ops_in, res_slots = layout["bwd"]
            operands = []
            for slot, k in ops_in:
                if slot == "value":
                    operands.append(value[k])
                else:  # a cotangent, of the output's dtype
                    operands.append(jnp.asarray(ct[k], dtype=_jax_dtype(jnp, params[k])))
            types = []
            for slot, k in res_slots:
                p = params[k]
                if slot == "grad":
                    types.append(jax.ShapeDtypeStruct(value[k].shape, _jax_dtype(jnp, p)))
                elif slot == "cotangent_copy":
                    types.append(jax.ShapeDtypeStruct(made[p["name"]].shape, _jax_dtype(jnp, p)))
                else:  # a replay's output or scratch
                    types.append(made[p["name"]])
            got = jax.ffi.ffi_call(target["bwd"], types, vmap_method="expand_dims")(*operands, **attrs)
            grads = {k: g for (slot, k), g in zip(res_slots, got) if slot == "grad"}
        out = []
        for p, a in zip(inputs, arrays):
            k = pos[p["name"]]
            if k in grads:
                out.append(grads[k])
            elif jnp.issubdtype(a.dtype, jnp.inexact):
                out.append(jnp.zeros(a.shape, a.dtype))
            else:
                out.append(np.zeros(a.shape, dtype=jax.dtypes.float0))
        return tuple(out)

    f.defvjp(f_fwd, f_bwd)
    return f
