"""Generated C equals the SX function; the library is cached by the function's hash."""
import numpy as np

from thermo_ddp.model.actuated import load_model
from thermo_ddp.codegen import compiled, library_path


def test_compiled_step_jacobians_equal_sx_and_are_cached():
    model = load_model(payload_kg=40.0)
    jac = model.step_jacobians(0.01)
    c_jac = compiled(jac)
    lib = library_path({jac.name(): jac})
    assert lib.is_file()
    stamp = lib.stat().st_mtime_ns
    x, u = model.state(q=[-1.0], v=[0.3]), np.array([-9.0])
    for a, b in zip(jac(x, u, 26.0), c_jac(x, u, 26.0)):
        assert np.allclose(np.array(a), np.array(b), rtol=1e-13, atol=1e-13)
    compiled(jac)
    assert lib.stat().st_mtime_ns == stamp  # reused, not rebuilt
    other = load_model(payload_kg=20.0).step_jacobians(0.01)
    assert library_path({other.name(): other}) != lib  # a changed model never loads a stale library
    assert library_path({jac.name(): jac}, ("-O1",)) != lib  # nor do other compiler flags
