"""The exact-PC code hook of core.Core.track_pc, without Python per
instruction.

A code hook makes Unicorn write each instruction's address to PC before it
runs; the core needs that write, not a call. So the hook's callback is a
function of Unicorn's own library that has no effect: `uc_arch_supported`
answers whether an architecture is built in, from its first argument, and
writes nothing. Called with the code hook's four arguments (engine,
address, size, user data) it reads only the first register and returns.
Should the binding's internals differ, the hook goes through the binding
with a Python function that does nothing (same behaviour, slower).
"""

import ctypes

from unicorn import UC_HOOK_CODE, UcError

try:
    from unicorn.unicorn_py3.unicorn import uc_hook_h as _uc_hook_h
    from unicorn.unicorn_py3.unicorn import uclib as _uclib

    NOOP_CALLBACK = ctypes.cast(_uclib.uc_arch_supported, ctypes.c_void_p)
except (ImportError, AttributeError):  # another binding
    NOOP_CALLBACK = None


def add_noop_code_hook(uc, begin, end):
    """A code hook on [begin, end] whose callback does nothing; its handle."""
    if NOOP_CALLBACK is None:
        return uc.hook_add(UC_HOOK_CODE, lambda *_: None, begin=begin, end=end)
    handle = _uc_hook_h()
    status = _uclib.uc_hook_add(uc._uch, ctypes.byref(handle), UC_HOOK_CODE, NOOP_CALLBACK,
                                None, ctypes.c_uint64(begin), ctypes.c_uint64(end))
    if status != 0:
        raise UcError(status)
    return handle.value


def del_noop_code_hook(uc, handle):
    if NOOP_CALLBACK is None:
        uc.hook_del(handle)
        return
    status = _uclib.uc_hook_del(uc._uch, _uc_hook_h(handle))
    if status != 0:
        raise UcError(status)
