"""Kernel launches with little Python work per call, for the kernels a step launches.

A Taichi kernel call does its work in Python before the launch: it derives the template key of
every argument (each ndarray's element type, dimension and gradient) to look up the compiled
kernel, then makes a launch context and sets every argument in it one by one (a few
microseconds each). With the 20 to 40 arguments of a step's kernels that costs about 0.4 ms
a call on a CPU, many times the kernel's own run for a few thousand circles.

`kernel` makes a Taichi kernel whose calls on a CPU skip that work:
- the first call with a new combination of template values and array types goes through
  Taichi as usual, which compiles the kernel and checks every argument; the compiled kernel
  is recorded under that combination;
- a call with a recorded combination binds a launch context to its arrays: each array is
  passed by its data pointer (on a CPU an ndarray's memory is plain host memory, which a
  kernel reads the same way through either kind of argument), so the context stays valid for
  as long as the arrays live;
- later calls with the same arrays (the same objects, still alive) reuse that context: they
  set only the scalar arguments that changed, and launch. Such a call costs a few
  microseconds of Python whatever the number of arrays: the arrays' identities are read in
  one C-level pass, a binding learns that one of its arrays is gone from the array's weak
  reference callback (no per-call check), and the kernel to launch is looked up once per
  binding.
Calls on a GPU, and calls with an argument this does not cover (an external array, a
template value that is not a plain number, a keyword argument), go through Taichi as usual.
The compiled kernel launched is the same, so results are the same bit for bit (tested).
"""
import ctypes
import operator
import weakref

import numpy as np
import taichi as ti
from taichi.lang import impl
from taichi.lang._ndarray import Ndarray
from taichi.types import ndarray_type, primitive_types, template

from .backend import on_recompile, on_restart

_NDARRAY, _FLOAT, _INT = 0, 1, 2
_SIGNED_IDS = {id(t) for t in (ti.i8, ti.i16, ti.i32, ti.i64, int)}
#: Template values the fast path keys on as they are (anything else goes through Taichi).
_PLAIN_TEMPLATES = (bool, int, float, str, type(ti.f32))
#: The scalar values Taichi takes for a real and for an integer argument.
_REAL_VALUES = (float, int, np.floating, np.integer)
_INT_VALUES = (int, np.integer)
#: Contexts and compiled combinations kept per kernel (at this many they start anew).
_MAX_ENTRIES = 64
#: Whether calls may take the fast path at all (tests turn it off to compare).
enabled = True
#: Every FastKernel made, so that a restart of the runtime can make each let go of it.
_kernels = weakref.WeakSet()


def _picker(indices):
    """A function that returns the tuple of the arguments at `indices` (in C for two or more)."""
    if len(indices) >= 2:
        return operator.itemgetter(*indices)
    return lambda args: tuple(args[i] for i in indices)


class _Binding:
    """A launch context with its arguments set for one set of arrays, the scalar values it
    holds and the kernel it launches. The arrays are weakly referenced: when one is gone the
    binding is marked dead (`alive`) and never used again (a new array may take its id)."""

    __slots__ = ("ctx", "arrays", "scalars", "launchable", "alive", "__weakref__")

    def __init__(self, ctx, arrays, scalars, launchable):
        self.ctx = ctx
        self.scalars = scalars
        self.launchable = launchable
        self.alive = True
        me = weakref.ref(self)

        def gone(_, me=me):
            binding = me()
            if binding is not None:
                binding.alive = False

        self.arrays = [weakref.ref(a, gone) for a in arrays]


class FastKernel:
    """A Taichi kernel called as usual; see the module's docstring for what differs."""

    def __init__(self, fn):
        self._kernel = ti.kernel(fn)
        self._primal = self._kernel._primal
        self.__name__ = fn.__name__
        self.__doc__ = fn.__doc__
        self.__wrapped__ = fn
        self._templates = []
        setters = []  # (argument index, kind) of each non-template argument, in slot order
        self._plannable = True
        for index, argument in enumerate(self._primal.arguments):
            anno = argument.annotation
            if isinstance(anno, template):
                self._templates.append(index)
            elif isinstance(anno, ndarray_type.NdarrayType):
                setters.append((index, _NDARRAY))
            elif id(anno) in primitive_types.real_type_ids:
                setters.append((index, _FLOAT))
            elif id(anno) in _SIGNED_IDS:
                setters.append((index, _INT))
            else:
                self._plannable = False
        self._arrays = [index for index, kind in setters if kind == _NDARRAY]
        self._pick_templates = _picker(self._templates)
        self._pick_arrays = _picker(self._arrays)
        self._array_slots = [((slot,), index) for slot, (index, kind) in enumerate(setters) if kind == _NDARRAY]
        # ((slot,), argument index, setter name, conversion, types Taichi accepts) of each scalar.
        self._scalar_slots = [((slot,), index, "set_arg_float", float, _REAL_VALUES) if kind == _FLOAT else
                              ((slot,), index, "set_arg_int", int, _INT_VALUES)
                              for slot, (index, kind) in enumerate(setters) if kind != _NDARRAY]
        returns = self._primal.return_type
        self._returns = None if returns is None else tuple(returns)
        if self._returns is not None and len(self._returns) != 1:
            self._plannable = False
        # The launch context's getter of a single return value of a plain type (else Taichi's).
        self._ret_getter = None
        if self._returns is not None and len(self._returns) == 1:
            ret = self._returns[0]
            if id(ret) in _SIGNED_IDS:
                self._ret_getter = "get_struct_ret_int"
            elif id(ret) in primitive_types.real_type_ids:
                self._ret_getter = "get_struct_ret_float"
        self._program = None
        self._cpu = False
        self._compiled = {}  # array types and template values -> compiled kernel
        self._bindings = {}  # template values and array identities -> _Binding
        _kernels.add(self)

    def _forget(self):
        """Drop the program, compiled kernels and launch contexts of the running runtime."""
        self._program = None
        self._drop_compiled()

    def _drop_compiled(self):
        """Drop the compiled kernels and launch contexts (the program stays)."""
        self._compiled = {}
        self._bindings = {}

    def _types_key(self, args):
        """The combination the compiled kernel depends on; None when an argument is not covered.

        Arrays count by the identity of their element type (hashing Taichi's type objects costs
        about a microsecond each); the entry keeps those objects, so an identity is not reused."""
        parts = []
        for index in self._templates:
            value = args[index]
            if not isinstance(value, _PLAIN_TEMPLATES):
                return None
            parts.append(value)
        for index in self._arrays:
            array = args[index]
            if not isinstance(array, Ndarray) or array.grad is not None:
                return None
            parts.append((id(array.element_type), len(array.shape)))
        return tuple(parts)

    def _through_taichi(self, args, key):
        """A call through Taichi, which compiles and checks; records the compiled kernel under
        `key` (`_types_key`)."""
        result = self._kernel(*args)
        if key is not None and key not in self._compiled:
            if len(self._compiled) >= _MAX_ENTRIES:
                self._compiled = {}
            compiled = self._primal.compiled_kernels[self._primal.ensure_compiled(*args)]
            types = [args[index].element_type for index in self._arrays]
            self._compiled[key] = (compiled, types)
        return result

    def _bind(self, args, key):
        """A new binding for these arguments, or None when no compiled kernel is recorded under
        their `key` (`_types_key`)."""
        entry = self._compiled.get(key) if key is not None else None
        if entry is None:
            return None
        compiled = entry[0]
        ctx = compiled.make_launch_context()
        arrays = [args[index] for index in self._arrays]
        for (slot, _), array in zip(self._array_slots, arrays):
            raw = array.arr
            ctx.set_arg_external_array_with_shape(slot, self._program.get_ndarray_data_ptr_as_int(raw),
                                                  raw.nelement() * raw.element_size(), list(array.shape), 0)
        scalars = []
        for slot, index, setter, convert, _ in self._scalar_slots:
            value = convert(args[index])
            getattr(ctx, setter)(slot, value)
            scalars.append(value)
        program = self._program
        launchable = program.compile_kernel(program.config(), program.get_device_caps(), compiled)
        return _Binding(ctx, arrays, scalars, launchable)

    def __call__(self, *args, **kwargs):
        if not (enabled and self._plannable) or kwargs or len(args) != len(self._primal.arguments):
            return self._kernel(*args, **kwargs)
        program = impl.get_runtime().prog
        if program is not self._program:
            # A new Taichi program (ti.init again): its kernels are compiled anew.
            self._program = program
            self._cpu = impl.current_cfg().arch in (ti.x64, ti.arm64)
            self._compiled = {}
            self._bindings = {}
        if not self._cpu:
            return self._kernel(*args)
        try:
            # Live arrays have distinct ids, and a binding whose array died is not alive.
            key = (self._pick_templates(args), tuple(map(id, self._pick_arrays(args))))
            binding = self._bindings.get(key)
        except TypeError:  # a template value that cannot be hashed
            return self._kernel(*args)
        if binding is not None and binding.alive:
            ctx = binding.ctx
            held = binding.scalars
            for k, (slot, index, setter, convert, accepted) in enumerate(self._scalar_slots):
                value = args[index]
                # Zeros are set again: -0.0 == 0.0, and the sign may matter. A value equal to the
                # one held was of a type Taichi takes (or converts to the same number).
                if value != held[k] or value == 0:
                    if not isinstance(value, accepted):
                        return self._kernel(*args)  # Taichi's error
                    value = convert(value)
                    getattr(ctx, setter)(slot, value)
                    held[k] = value
        else:
            for _, index, _, _, accepted in self._scalar_slots:
                if not isinstance(args[index], accepted):
                    return self._kernel(*args)  # Taichi's error
            types = self._types_key(args)
            binding = self._bind(args, types)
            if binding is None:
                return self._through_taichi(args, types)
            if len(self._bindings) >= _MAX_ENTRIES:
                self._bindings = {}
            self._bindings[key] = binding
            ctx = binding.ctx
        program.launch_kernel(binding.launchable, ctx)
        if self._returns is None:
            return None
        program.synchronize()
        if self._ret_getter is not None:
            return getattr(ctx, self._ret_getter)((0,))
        return self._primal.construct_kernel_ret(ctx, self._returns[0], (0,))


@on_restart
def _forget_runtime():
    """Before `circles.init` restarts the runtime, every fast kernel lets go of the running
    program and of what it compiled and bound. Kept past the restart, the old program's last
    reference was dropped at a later call, after `ti.reset` had finalised it, and the process
    then crashed within a few restarts (Taichi 1.7 on a CPU)."""
    for fast in list(_kernels):
        fast._forget()


@on_recompile
def _forget_compiled():
    """When `backend.compile_for` changes how kernels compile, every fast kernel drops what it
    compiled and bound (the program stays)."""
    for fast in list(_kernels):
        fast._drop_compiled()


def kernel(fn):
    """`ti.kernel`, with the fast calls of `FastKernel`."""
    return FastKernel(fn)


def host_view(arr):
    """A numpy array over the memory of a 1-D ndarray of float64 on a CPU (no copy, no launch:
    `to_numpy` costs a kernel launch, about 0.1 ms), or None elsewhere. Read it only after a
    synchronisation (a kernel that returns a value synchronises); it is valid while `arr` lives,
    so keep both."""
    if impl.current_cfg().arch not in (ti.x64, ti.arm64) or arr.dtype != ti.f64 or len(arr.shape) != 1:
        return None
    program = impl.get_runtime().prog
    address = program.get_ndarray_data_ptr_as_int(arr.arr)
    return np.ctypeslib.as_array((ctypes.c_double * arr.shape[0]).from_address(address))
