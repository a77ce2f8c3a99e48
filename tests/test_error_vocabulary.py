"""One error vocabulary: the C enums are the single source of the status codes.

- the parser of dopus_codegen.vocabulary reads the same values as the C compiler does;
- it picks up an enum member it has never seen (no hand-kept Python copy);
- the two backends fail the same way (same class, same status, same QP status) for a
  non-finite measurement, an infeasible QP and a QP stopped by its iteration limit.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from dopus_codegen import vocabulary
from dopus_codegen.codegen.flags import STRICT_CFLAGS
from dopus_codegen.cnames import rename_placeholder
from dopus_codegen.errors import DopusError, qp_status_code, status_code


def test_parser_agrees_with_the_c_compiler(tmp_path):
    """Every parsed member, printed by a C program compiled against the generated headers of
    generated/unicycle (the prefix renamed as the generator renames it)."""
    folder = Path(__file__).resolve().parent.parent / "generated" / "unicycle"
    enums = vocabulary.runtime_enums()
    rows = [(c, name, rename_placeholder(e.identifiers[name], "unicycle"))
            for c, e in sorted(enums.items()) for name in e.names()]
    assert len(rows) >= 30
    src = tmp_path / "enums.c"
    src.write_text('#include <stdio.h>\n#include "unicycle_solver.h"\nint main(void)\n{\n'
                   + "".join(f'    printf("%d\\n", (int){ident});\n' for _, _, ident in rows) + "    return 0;\n}\n")
    exe = tmp_path / "enums"
    subprocess.run(["cc", *STRICT_CFLAGS, f"-I{folder}", str(src), "-o", str(exe)], check=True)
    printed = [int(v) for v in subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()]
    assert printed == [enums[c].codes[name] for c, name, _ in rows]
    # and the status texts are those of the generated dopus_status_string
    texts = vocabulary.parse_status_strings((folder / "unicycle_solver.c").read_text())
    st = enums["dopus_status"]
    assert {rename_placeholder(i, "unicycle"): st.descriptions[st.codes[n]] for n, i in st.identifiers.items()} == texts


def test_parser_picks_up_new_members():
    text = """
    enum dopus_status {
        DOPUS_OK = 0,
        DOPUS_ERR_QP = 1,        /* QP not solved, see
                                    the QP status */
        DOPUS_ERR_LATE,          /* a member without a value, commas, in, its comment */
        DOPUS_ERR_NEW = 12       /* added later */
    };
    enum dopus_phase { DOPUS_PHASE_A = 0, DOPUS_PHASE_B = 1, DOPUS_N_PHASES = 2 };
    """
    enums = vocabulary.parse_enums(text)
    st = enums["dopus_status"]
    assert st.codes == {"ok": 0, "qp": 1, "late": 2, "new": 12}
    assert st.descriptions[1] == "QP not solved, see the QP status"
    assert st.descriptions[2] == "a member without a value, commas, in, its comment"
    assert st.name(12) == "new" and st.name(7) == "unknown(7)"
    assert enums["dopus_phase"].names() == ("a", "b")
    texts = vocabulary.parse_status_strings('case DOPUS_OK:\n return "ok";\n case DOPUS_ERR_NEW: return "new \\"x\\"";')
    assert texts == {"DOPUS_OK": "ok", "DOPUS_ERR_NEW": 'new "x"'}


# ------------------------------------------------------------------ the same failure, both backends
@pytest.fixture(scope="module")
def small_disc():
    """x' = u with |u| <= 1 and the terminal constraint x_N = 0: a QP is infeasible when the
    measured state is farther than N dt from 0 (the dynamics are linear, so the QP is exact)."""
    from dopus_codegen import Ocp, build_functions

    ocp = Ocp("reach")
    x = ocp.state("x")
    u = ocp.control("u", lb=-1.0, ub=1.0)
    ocp.dynamics(u)
    ocp.stage_least_squares(u, weights=[1.0])
    ocp.terminal_constraint(x, lb=0.0, ub=0.0)
    ocp.horizon(N=4, dt=0.25)
    ocp.initial_state([0.5])
    return build_functions(ocp)


def _backends(disc):
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver

    out = []
    for cls in (CSolver, ReferenceDopus):
        b = cls(disc, M=1, mode="fixed")
        b.init(disc.x0)
        out.append(b)
    return out


def _failure(backend, call):
    with pytest.raises(DopusError) as ei:
        call(backend)
    return type(ei.value), ei.value.status, ei.value.qp_status


def test_same_failures_both_backends(small_disc):
    d = small_disc
    cases = {
        "non-finite measurement": (lambda b: b.feedback([np.nan]), ("nonfinite_input", None)),
        "infeasible QP": (lambda b: b.feedback([3.0]), ("qp", "primal_infeasible")),
    }
    for label, (call, (status, qp_status)) in cases.items():
        got = []
        for b in _backends(d):
            x_before = b.x.copy()
            got.append(_failure(b, call))
            np.testing.assert_array_equal(b.x, x_before)            # no step
            assert b.status == status_code(status), label
            b.feedback(d.x0)                                         # the next good call works
        want = (DopusError, status_code(status), None if qp_status is None else qp_status_code(qp_status))
        assert got == [want, want], label
    # QP iteration limit: one interior-point iteration does not solve a QP with active bounds
    # (a measurement more than one state scale from the prediction 0.5: the interior point
    # from the start, not the active-set start of docs/algorithm.md section 4)
    got = []
    for b in _backends(d):
        b.set_qp_max_iter(1)
        got.append(_failure(b, lambda b: b.feedback([-0.95])))
        assert b.qp_status == qp_status_code("max_iter")
    want = (DopusError, status_code("qp"), qp_status_code("max_iter"))
    assert got == [want, want]


def test_generated_folder_speaks_the_runtime_codes():
    """The C handle reads the codes from the generated headers it was built from; they are
    the runtime's (the renaming changes the prefix only)."""
    folder = Path(__file__).resolve().parent.parent / "generated" / "robot_arm"
    gen, run = vocabulary.generated_enums(str(folder), "robot_arm"), vocabulary.runtime_enums()
    assert sorted(gen) == sorted(run)
    for c_name in run:
        assert gen[c_name].codes == run[c_name].codes, c_name
    assert gen["dopus_status"].descriptions == run["dopus_status"].descriptions
    assert gen["dopus_status"].identifiers["qp"] == "ROBOT_ARM_ERR_QP"
