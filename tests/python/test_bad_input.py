"""Every kind of bad input raises TypeError/ValueError with a message naming the argument, and
skin() validates everything before it writes to ``out``."""

from __future__ import annotations

import dqskin
import numpy as np
import pytest

V = 5  # vertices of the small valid setup
B = 2  # bones
SENTINEL = 7.25  # what `out` holds before a failing call; it must still hold it afterwards
# Values computed from exact inputs with a couple of float32 roundings (ulp(3) = 2.4e-7).
ROUNDING_TOL = 1e-6


def valid():
    """A small valid skin() call: positional args and keyword args."""
    positions = np.arange(V * 3, dtype=np.float32).reshape(V, 3) / 10
    infl = dqskin.Influences(np.array([0, 1, 2, 4, 4, 5]), np.array([0, 1, 0, 1, 1]), np.float32([1, 1, 0.5, 0.5, 1]), B)
    deform = np.tile(np.eye(4, dtype=np.float32), (B, 1, 1))
    deform[1, :3, 3] = [0.0, 1.0, 0.0]
    rest = np.tile(np.eye(4, dtype=np.float32), (B, 1, 1))
    return dict(positions=positions, influences=infl, deform=deform, rest=rest)


def call(args, **kw):
    a = dict(args)
    return dqskin.skin(a.pop("positions"), a.pop("influences"), a.pop("deform"), a.pop("rest"), **a, **kw)


def test_the_valid_setup_works():
    out = np.full((V, 3), SENTINEL, np.float32)
    for method in ("linear", "dual_quaternion", "blend"):
        assert call(valid(), method=method, out=out) is out
        assert np.all(np.isfinite(out)) and not np.any(out == SENTINEL)


def with_(**changes):
    def make():
        a = valid()
        for k, v in changes.items():
            a[k] = v(a) if callable(v) else v
        return a

    return make


def deform_with(fn):
    def change(a):
        d = a["deform"].copy()
        fn(d)
        return d

    return change


def _set(d, idx, value):
    d[idx] = value


def transposed_positions(a):
    return np.ascontiguousarray(a["positions"].T).T  # (V, 3) Fortran-ordered view


def strided_positions(a):
    big = np.zeros((2 * V, 3), np.float32)
    big[::2] = a["positions"]
    return big[::2]


def not_affine_premat(a):
    m = np.eye(4, dtype=np.float32)
    m[3, 0] = 0.5
    return m


def nan_premat(a):
    m = np.eye(4, dtype=np.float32)
    m[0, 3] = np.nan
    return m


SKIN_CASES = [
    # (id, make the args, extra keywords, exception, message pattern)
    ("positions float64", with_(positions=lambda a: a["positions"].astype(np.float64)), {}, TypeError, r"positions.*float32"),
    ("positions list", with_(positions=lambda a: a["positions"].tolist()), {}, TypeError, r"positions must be a numpy array"),
    ("positions wrong shape", with_(positions=lambda a: a["positions"][:, :2].copy()), {}, ValueError, r"positions must have shape"),
    ("positions wrong count", with_(positions=lambda a: a["positions"][:-1].copy()), {}, ValueError, r"positions must have shape"),
    ("positions 1-D", with_(positions=lambda a: a["positions"].ravel()), {}, ValueError, r"positions must have shape"),
    ("positions transposed", with_(positions=transposed_positions), {}, ValueError, r"positions must be C-contiguous"),
    ("positions strided", with_(positions=strided_positions), {}, ValueError, r"positions must be C-contiguous"),
    (
        "deform bone count",
        with_(deform=lambda a: np.tile(np.eye(4, dtype=np.float32), (B + 1, 1, 1))),
        {},
        ValueError,
        r"deform must have shape",
    ),
    ("deform float64", with_(deform=lambda a: a["deform"].astype(np.float64)), {}, TypeError, r"deform.*float32"),
    ("deform 3x4", with_(deform=lambda a: a["deform"][:, :3, :].copy()), {}, ValueError, r"deform must have shape"),
    ("deform list", with_(deform=lambda a: a["deform"].tolist()), {}, TypeError, r"deform must be a numpy array"),
    (
        "deform not contiguous",
        with_(deform=lambda a: np.ascontiguousarray(a["deform"].transpose(0, 2, 1)).transpose(0, 2, 1)),
        {},
        ValueError,
        r"deform must be C-contiguous",
    ),
    ("rest float64", with_(rest=lambda a: a["rest"].astype(np.float64)), {}, TypeError, r"rest.*float32"),
    ("deform NaN", with_(deform=deform_with(lambda d: _set(d, (1, 0, 3), np.nan))), {}, ValueError, r"deform contains a NaN"),
    ("deform inf", with_(deform=deform_with(lambda d: _set(d, (0, 2, 2), np.inf))), {}, ValueError, r"deform contains a NaN or infinite"),
    (
        "deform not affine",
        with_(deform=deform_with(lambda d: _set(d, (1, 3, 0), 0.5))),
        {"method": "linear"},
        ValueError,
        r"deform matrix of bone 1 is not affine",
    ),
    (
        "deform w != 1",
        with_(deform=deform_with(lambda d: _set(d, (0, 3, 3), 2.0))),
        {},
        ValueError,
        r"deform matrix of bone 0 is not affine",
    ),
    ("rest missing dqs", with_(rest=None), {"method": "dual_quaternion"}, ValueError, r"rest is required"),
    ("rest missing blend", with_(rest=None), {"method": "blend"}, ValueError, r"rest is required"),
    (
        "rest not invertible",
        with_(rest=lambda a: np.stack([np.eye(4, dtype=np.float32), np.diag(np.float32([1, 0, 1, 1]))])),
        {},
        ValueError,
        r"rest matrix of bone 1 is not invertible",
    ),
    ("rest wrong count", with_(rest=lambda a: a["rest"][:1].copy()), {}, ValueError, r"rest must have shape"),
    ("rest NaN", with_(rest=lambda a: np.full((B, 4, 4), np.nan, np.float32)), {}, ValueError, r"rest contains a NaN"),
    ("rest not affine", with_(rest=deform_with(lambda d: _set(d, (0, 3, 1), 1.0))), {}, ValueError, r"rest matrix of bone 0 is not affine"),
    (
        "unknown method",
        valid,
        {"method": "bbone"},
        ValueError,
        r"method must be a dqskin.Method, one of 'linear', 'dual_quaternion', 'blend', 'centers_of_rotation'",
    ),
    (
        "blend with linear",
        valid,
        {"method": "linear", "blend": np.full(V, 0.5, np.float32)},
        ValueError,
        r"blend is only used with method='blend'",
    ),
    (
        "blend with dqs",
        valid,
        {"method": "dual_quaternion", "blend": np.full(V, 0.5, np.float32)},
        ValueError,
        r"blend is only used with method='blend'",
    ),
    (
        "blend above 1",
        valid,
        {"method": "blend", "blend": np.float32([0, 0.5, 1.5, 1, 0])},
        ValueError,
        r"blend amount\[2\] = 1.5 is outside \[0, 1\]",
    ),
    (
        "blend negative",
        valid,
        {"method": "blend", "blend": np.float32([0, -0.1, 0, 1, 0])},
        ValueError,
        r"blend amount\[1\].*outside \[0, 1\]",
    ),
    ("blend NaN", valid, {"method": "blend", "blend": np.float32([0, 0, 0, np.nan, 0])}, ValueError, r"blend amount\[3\] = NaN"),
    ("blend wrong length", valid, {"method": "blend", "blend": np.zeros(V + 1, np.float32)}, ValueError, r"blend must have shape"),
    ("blend float64", valid, {"method": "blend", "blend": np.zeros(V)}, TypeError, r"blend.*float32"),
    ("blend_factor above 1", valid, {"method": "blend", "blend_factor": 1.5}, ValueError, r"blend_factor = 1.5 is outside \[0, 1\]"),
    ("blend_factor negative", valid, {"method": "blend", "blend_factor": -0.5}, ValueError, r"blend_factor.*outside \[0, 1\]"),
    ("blend_factor NaN", valid, {"method": "blend", "blend_factor": float("nan")}, ValueError, r"blend_factor must be finite"),
    ("mask wrong length", valid, {"mask": np.ones(V - 1, np.float32)}, ValueError, r"mask must have shape"),
    ("mask above 1", valid, {"mask": np.float32([1, 1, 1, 2, 1])}, ValueError, r"mask\[3\] = 2 is outside \[0, 1\]"),
    ("mask negative", valid, {"mask": np.float32([-1, 1, 1, 1, 1])}, ValueError, r"mask\[0\] = -1 is outside \[0, 1\]"),
    ("mask NaN", valid, {"mask": np.float32([1, np.nan, 1, 1, 1])}, ValueError, r"mask\[1\] = NaN"),
    ("mask float64", valid, {"mask": np.ones(V)}, TypeError, r"mask.*float32"),
    ("premat NaN", valid, {"premat": nan_premat(None)}, ValueError, r"premat contains a NaN"),
    ("premat not affine", valid, {"premat": not_affine_premat(None)}, ValueError, r"premat is not affine"),
    ("premat wrong shape", valid, {"premat": np.eye(3, dtype=np.float32)}, ValueError, r"premat must have shape"),
    ("premat not numbers", valid, {"premat": "identity"}, TypeError, r"premat must be an array of numbers"),
    (
        "postmat inf",
        valid,
        {"postmat": np.where(np.eye(4) > 0, np.inf, 0).astype(np.float32)},
        ValueError,
        r"postmat contains a NaN or infinite",
    ),
    ("postmat not affine", valid, {"postmat": not_affine_premat(None)}, ValueError, r"postmat is not affine"),
]


@pytest.mark.parametrize("make, kw, exc, pattern", [c[1:] for c in SKIN_CASES], ids=[c[0] for c in SKIN_CASES])
def test_skin_rejects_bad_input_and_leaves_out_untouched(make, kw, exc, pattern):
    args = make()
    out = np.full((V, 3), SENTINEL, np.float32)
    with pytest.raises(exc, match=pattern):
        call(args, out=out, **kw)
    assert np.all(out == SENTINEL), "skin() wrote to out before rejecting its input"
    # The same error without `out` (the check does not depend on it).
    with pytest.raises(exc, match=pattern):
        call(args, **kw)


def test_positions_float64_message_says_how_to_fix_it():
    a = valid()
    with pytest.raises(TypeError, match=r"positions must have dtype float32, got float64") as info:
        call(dict(a, positions=a["positions"].astype(np.float64)))
    assert "np.asarray(positions, dtype=np.float32)" in str(info.value)


@pytest.mark.parametrize(
    "make_out, exc, pattern",
    [
        (lambda: np.zeros((V, 2), np.float32), ValueError, r"out must have shape"),
        (lambda: np.zeros((V + 1, 3), np.float32), ValueError, r"out must have shape"),
        (lambda: np.zeros((V, 3), np.float64), TypeError, r"out must have dtype float32"),
        (lambda: np.zeros((V, 3), np.float32).tolist(), TypeError, r"out must be a numpy array"),
        (lambda: np.zeros((3, V), np.float32).T, ValueError, r"out must be C-contiguous"),
    ],
    ids=["shape", "count", "float64", "list", "transposed"],
)
def test_bad_out(make_out, exc, pattern):
    out = make_out()
    before = np.array(out, copy=True)
    with pytest.raises(exc, match=pattern):
        call(valid(), out=out)
    np.testing.assert_array_equal(np.asarray(out), before)


def test_out_must_not_be_positions():
    a = valid()
    positions = a["positions"]
    before = positions.copy()
    with pytest.raises(ValueError, match=r"out must not be \(or overlap\) one of the input arrays"):
        call(a, out=positions, method="dual_quaternion")
    np.testing.assert_array_equal(positions, before)


def test_out_must_not_overlap_positions():
    a = valid()
    buf = np.zeros((2 * V, 3), np.float32)
    buf[:V] = a["positions"]
    positions, out = buf[:V], buf[V // 2 : V // 2 + V]
    assert np.shares_memory(positions, out)
    before = buf.copy()
    with pytest.raises(ValueError, match=r"out must not be \(or overlap\)"):
        call(dict(a, positions=positions), out=out)
    np.testing.assert_array_equal(buf, before)


@pytest.mark.parametrize("which", ["mask", "blend"])
def test_out_must_not_overlap_mask_or_blend(which):
    buf = np.zeros(V * 3, np.float32)  # out is the whole buffer; the per-vertex array is a view of it
    kw = {"mask": buf[:V]} if which == "mask" else {"method": "blend", "blend": buf[V : 2 * V]}
    with pytest.raises(ValueError, match=r"out must not be \(or overlap\)"):
        call(valid(), out=buf.reshape(V, 3), **kw)
    assert not buf.any()


def test_out_must_be_writeable():
    out = np.full((V, 3), SENTINEL, np.float32)
    out.flags.writeable = False
    with pytest.raises(ValueError, match=r"out is read-only"):
        call(valid(), out=out)
    assert np.all(out == SENTINEL)


@pytest.mark.parametrize("bad", [None, "influences", (np.array([0, 1]), np.array([0]), np.float32([1]))], ids=["None", "str", "tuple"])
def test_influences_must_be_an_influences(bad):
    a = valid()
    with pytest.raises(TypeError, match=r"influences must be a dqskin.Influences"):
        call(dict(a, influences=bad))


def test_influences_for_other_vertex_count():
    a = valid()
    infl = dqskin.Influences(np.array([0, 1]), np.array([0]), np.float32([1]), B)
    with pytest.raises(ValueError, match=r"positions must have shape \(1, 3\)"):
        call(dict(a, influences=infl))


# ---------------------------------------------------------------------------------------------
# Influences

I32 = np.int32
F32 = np.float32


@pytest.mark.parametrize(
    "offsets, bones, weights, bone_count, exc, pattern",
    [
        (np.array([1, 2]), np.array([0, 1]), F32([1, 1]), 2, ValueError, r"offsets\[0\] must be 0, got 1"),
        (np.array([0, 2, 1, 2]), np.array([0, 1]), F32([1, 1]), 2, ValueError, r"offsets must not decrease"),
        (np.array([0, 1]), np.array([0, 1]), F32([1, 1]), 2, ValueError, r"offsets\[-1\] is 1 but there are 2 influences"),
        (np.array([0, 3]), np.array([0, 1]), F32([1, 1]), 2, ValueError, r"offsets\[-1\] is 3"),
        (np.array([], I32), np.array([], I32), F32([]), 2, ValueError, r"offsets must have one entry per vertex plus one"),
        (np.array([0, 2]), np.array([0, 4]), F32([1, 1]), 4, ValueError, r"bones\[1\] = 4 is out of range: bone_count = 4"),
        (np.array([0, 2]), np.array([0, 2]), F32([1, 1]), 2, ValueError, r"bones\[1\] = 2 is out of range"),
        (np.array([0, 2]), np.array([-1, 0]), F32([1, 1]), 2, ValueError, r"bones\[0\] = -1 is out of range"),
        (np.array([0, 1]), np.array([0]), F32([1]), 0, ValueError, r"bones\[0\] = 0 is out of range: bone_count = 0"),
        (np.array([0, -1]), np.array([], I32), F32([]), 1, ValueError, r"offsets\[1\] = -1 is out of range"),
        (np.array([0, 2]), np.array([0, 1]), F32([1, -0.1]), 2, ValueError, r"weights\[1\] = -0.1 is not a finite non-negative number"),
        (np.array([0, 2]), np.array([0, 1]), F32([np.nan, 1]), 2, ValueError, r"weights\[0\] = NaN is not a finite non-negative number"),
        (np.array([0, 2]), np.array([0, 1]), F32([1, np.inf]), 2, ValueError, r"weights\[1\] = inf is not a finite"),
        (np.array([0.0, 2.0]), np.array([0, 1]), F32([1, 1]), 2, TypeError, r"offsets must have an integer dtype"),
        (np.array([0, 2]), np.array([0.0, 1.0]), F32([1, 1]), 2, TypeError, r"bones must have an integer dtype"),
        (np.array([0, 2]), np.array([0, 1]), np.array([1.0, 1.0]), 2, TypeError, r"weights must have dtype float32"),
        ([0, 2], np.array([0, 1]), F32([1, 1]), 2, TypeError, r"offsets must be a numpy array"),
        (np.array([0, 2]), np.array([0, 1]), [1.0, 1.0], 2, TypeError, r"weights must be a numpy array"),
        (np.array([0, 2]), np.array([0, 1]), F32([1]), 2, ValueError, r"bones has 2 entries but weights has 1"),
        (np.array([0, 1]), np.array([0]), F32([1, 1]), 2, ValueError, r"bones has 1 entries but weights has 2"),
        (np.array([[0, 1]]), np.array([0]), F32([1]), 2, ValueError, r"offsets must be one-dimensional"),
        (np.array([0, 1]), np.array([0]), F32([[1]]), 2, ValueError, r"weights must have shape"),
        (np.array([0, 1]), np.array([0]), F32([1]), -1, ValueError, r"bone_count must be"),
    ],
    ids=[
        "offsets-start",
        "offsets-decrease",
        "offsets-last-short",
        "offsets-last-long",
        "offsets-empty",
        "bone-too-big",
        "bone-equal-count",
        "bone-negative",
        "zero-bones",
        "offset-negative",
        "weight-negative",
        "weight-nan",
        "weight-inf",
        "offsets-float",
        "bones-float",
        "weights-float64",
        "offsets-list",
        "weights-list",
        "fewer-weights",
        "fewer-bones",
        "offsets-2d",
        "weights-2d",
        "bone-count-negative",
    ],
)
def test_influences_reject(offsets, bones, weights, bone_count, exc, pattern):
    with pytest.raises(exc, match=pattern):
        dqskin.Influences(offsets, bones, weights, bone_count)


@pytest.mark.parametrize(
    "bones, weights, exc, pattern",
    [
        (np.zeros((3, 2), I32), np.ones((3, 3), F32), ValueError, r"bones must have the same shape as weights \(3, 3\)"),
        (np.zeros((3, 2), I32), np.ones((3, 2)), TypeError, r"weights must have dtype float32"),
        (np.zeros((3, 2)), np.ones((3, 2), F32), TypeError, r"bones must have an integer dtype"),
        (np.full((3, 2), 5, I32), np.ones((3, 2), F32), ValueError, r"bones\[\d\] = 5 is out of range"),
        (np.zeros((3, 2), I32), -np.ones((3, 2), F32), ValueError, r"weights\[0\] = -1 is not a finite non-negative"),
        (np.zeros((3, 2), I32), np.ones(3, F32), ValueError, r"weights must have shape \(V, K\)"),
    ],
    ids=["shape-mismatch", "weights-float64", "bones-float", "bone-range", "weight-negative", "weights-1d"],
)
def test_influences_from_dense_reject(bones, weights, exc, pattern):
    with pytest.raises(exc, match=pattern):
        dqskin.Influences.from_dense(bones, weights, 3)


# ---------------------------------------------------------------------------------------------
# Blending, interpolation, hierarchies

IDENTITY = np.float32([1, 0, 0, 0, 0, 0, 0, 0])
TWO = np.stack([IDENTITY, np.float32([0, 0, 1, 0, 0, 0.5, 0, 0])])


@pytest.mark.parametrize("fn", ["dlb", "dib"])
@pytest.mark.parametrize(
    "transforms, weights, exc, pattern",
    [
        (np.zeros((0, 8), F32), np.zeros(0, F32), ValueError, r"transforms must not be empty"),
        (TWO, F32([1.0]), ValueError, r"weights has 1 entries but there are 2 transforms"),
        (TWO, F32([1, 1, 1]), ValueError, r"weights has 3 entries but there are 2 transforms"),
        (TWO, F32([1.0, -0.5]), ValueError, r"weights\[1\] is negative or not finite"),
        (TWO, F32([0.0, 0.0]), ValueError, r"weights sum to zero"),
        (np.stack([IDENTITY, np.zeros(8, F32)]), F32([1, 1]), ValueError, r"transforms\[1\] has a zero real part"),
        (np.stack([IDENTITY, np.float32([np.nan, 0, 0, 0, 0, 0, 0, 0])]), F32([1, 1]), ValueError, r"transforms contains a NaN"),
        (TWO, F32([1, np.nan]), ValueError, r"weights contains a NaN or infinite value \(flat index 1\)"),
        (TWO, F32([1, np.inf]), ValueError, r"weights contains a NaN or infinite value"),
        (np.zeros((2, 7), F32), F32([1, 1]), ValueError, r"transforms must have shape \(N, 8\)"),
        (IDENTITY, F32([1]), ValueError, r"transforms must have shape \(N, 8\)"),
        (TWO, F32([[1, 1]]), ValueError, r"weights must have shape \(N,\)"),
        ("abc", F32([1]), TypeError, r"transforms must be an array of numbers"),
    ],
    ids=[
        "empty",
        "fewer-weights",
        "more-weights",
        "negative",
        "all-zero",
        "zero-dq",
        "nan-transform",
        "nan-weight",
        "inf-weight",
        "shape-7",
        "shape-1d",
        "weights-2d",
        "not-numbers",
    ],
)
def test_blend_rejects(fn, transforms, weights, exc, pattern):
    with pytest.raises(exc, match=pattern):
        getattr(dqskin, fn)(transforms, weights)


@pytest.mark.parametrize("precision", [-1e-6, float("nan"), float("inf")])
def test_dib_rejects_bad_precision(precision):
    with pytest.raises(ValueError, match=r"precision must be (a )?finite"):
        dqskin.dib(TWO, F32([1, 1]), precision=precision)


def notes(exc):
    return "\n".join(getattr(exc, "__notes__", []))


def test_wrong_python_types_for_scalar_arguments_name_the_argument():
    """Plain Python arguments of the wrong kind: a TypeError whose message names the argument."""
    a = valid()
    with pytest.raises(TypeError, match="method must be a dqskin.Method or a string"):
        call(a, method=3)
    with pytest.raises(TypeError, match="blend_factor must be a real number"):
        call(a, method="blend", blend_factor="half")
    with pytest.raises(TypeError, match="bone_count must be an integer"):
        dqskin.Influences(np.array([0, 1]), np.array([0]), F32([1]), "two")
    # Huge integers: ValueError naming the argument, not OverflowError.
    with pytest.raises(ValueError, match="bone_count must be between"):
        dqskin.Influences(np.array([0, 1]), np.array([0]), F32([1]), 10**30)
    # A negative count is bad input like any other: ValueError naming the argument.
    with pytest.raises(ValueError, match="max_iterations"):
        dqskin.dib(TWO, F32([1, 1]), max_iterations=-1)


@pytest.mark.parametrize(
    "a, b, t, exc, pattern",
    [
        (np.zeros(8, F32), IDENTITY, 0.5, ValueError, r"^a has a zero real part"),
        (IDENTITY, np.zeros(8, F32), 0.5, ValueError, r"^b has a zero real part"),
        (IDENTITY[:7], IDENTITY, 0.5, ValueError, r"a must have shape \(8,\)"),
        (IDENTITY, IDENTITY, float("nan"), ValueError, r"t must be finite"),
        (IDENTITY, IDENTITY, F32([0, np.nan]), ValueError, r"t contains a NaN"),
        (IDENTITY, IDENTITY, F32([[0.5]]), ValueError, r"t must have shape \(T,\)"),
        (np.float32([np.inf, 0, 0, 0, 0, 0, 0, 0]), IDENTITY, 0.5, ValueError, r"a contains a NaN or infinite"),
    ],
    ids=["zero-a", "zero-b", "short-a", "nan-t", "nan-in-t-array", "t-2d", "inf-a"],
)
def test_sclerp_rejects(a, b, t, exc, pattern):
    with pytest.raises(exc, match=pattern):
        dqskin.sclerp(a, b, t)


@pytest.mark.parametrize(
    "q0, q1, t, pattern",
    [
        (np.zeros(4, F32), F32([1, 0, 0, 0]), 0.5, r"q0 must be a non-zero quaternion"),
        (F32([1, 0, 0, 0]), np.zeros(4, F32), 0.5, r"q1 must be a non-zero quaternion"),
        (F32([1, 0, 0]), F32([1, 0, 0, 0]), 0.5, r"q0 must have shape \(4,\)"),
        (F32([1, 0, 0, 0]), F32([1, 0, 0, 0]), float("inf"), r"t must be finite"),
    ],
)
def test_slerp_rejects(q0, q1, t, pattern):
    with pytest.raises(ValueError, match=pattern):
        dqskin.slerp(q0, q1, t)


@pytest.mark.parametrize("fn", ["squad", "squad_control_points"])
@pytest.mark.parametrize(
    "keys, pattern",
    [
        (np.zeros((0, 4), F32), r"keys must contain at least one rotation"),
        (np.stack([F32([1, 0, 0, 0]), np.zeros(4, F32)]), r"keys\[1\] is a zero quaternion"),
        (np.zeros((3, 3), F32), r"keys must have shape \(K, 4\)"),
        (np.float32([[1, 0, 0, np.nan]]), r"keys contains a NaN"),
    ],
    ids=["empty", "zero-key", "shape", "nan"],
)
def test_squad_rejects(fn, keys, pattern):
    f = getattr(dqskin, fn)
    with pytest.raises(ValueError, match=pattern):
        f(keys, 0.5) if fn == "squad" else f(keys)


LOCALS3 = np.tile(IDENTITY, (3, 1))


@pytest.mark.parametrize(
    "parents, locals_, exc, pattern",
    [
        (np.array([1, 2, 0]), LOCALS3, ValueError, r"parents form a cycle through bone"),
        (np.array([-1, 1, 0]), LOCALS3, ValueError, r"parents form a cycle through bone 1"),
        (np.array([-1, 5, 0]), LOCALS3, ValueError, r"parents\[1\] = 5 is not a bone index \(use -1 for a root\)"),
        (np.array([-1, 3, 0]), LOCALS3, ValueError, r"parents\[1\] = 3 is not a bone index"),
        (np.array([-1, 0]), LOCALS3, ValueError, r"parents has 2 entries but locals has 3"),
        (np.array([-1, 0, 1, 2]), LOCALS3, ValueError, r"parents has 4 entries but locals has 3"),
        (np.array([-1.0, 0.0, 1.0]), LOCALS3, TypeError, r"parents must be an array of integers"),
        (np.array([[-1, 0, 1]]), LOCALS3, ValueError, r"parents must be one-dimensional"),
        (np.array([-1, 0, 1]), LOCALS3[:, :4].copy(), ValueError, r"locals must have shape \(N, 8\)"),
        (np.array([-1, 0, 1]), np.stack([IDENTITY, np.zeros(8, F32), IDENTITY]), ValueError, r"locals\[1\] has a zero real part"),
    ],
    ids=[
        "cycle-3",
        "self-parent",
        "out-of-range",
        "parent-equals-count",
        "fewer-parents",
        "more-parents",
        "float-parents",
        "2d-parents",
        "locals-shape",
        "zero-local",
    ],
)
def test_forward_kinematics_rejects(parents, locals_, exc, pattern):
    with pytest.raises(exc, match=pattern):
        dqskin.forward_kinematics(parents, locals_)


# ---------------------------------------------------------------------------------------------
# DualQuat and conversions


@pytest.mark.parametrize(
    "matrix, pattern",
    [
        (np.diag(F32([2, 1, 1, 1])), r"matrix: .*not a rigid transform"),
        (np.diag(F32([1.01, 1, 1, 1])), r"matrix: .*not a rigid transform"),
        (np.diag(F32([-1, 1, 1, 1])), r"matrix: .*not a rigid transform"),
        (np.array([[1, 0.3, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], F32), r"matrix: .*not a rigid"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0.5, 0, 0, 1]], F32), r"matrix: .*not affine"),
        (np.where(np.eye(4) > 0, np.nan, 0).astype(F32), r"matrix contains a NaN"),
    ],
    ids=["scaled", "slightly-scaled", "mirrored", "sheared", "not-affine", "nan"],
)
def test_dualquat_from_matrix_rejects_non_rigid(matrix, pattern):
    with pytest.raises(ValueError, match=pattern):
        dqskin.DualQuat.from_matrix(matrix)
    with pytest.raises(ValueError, match=r"matrices\[1\]: .*|matrices contains a NaN"):
        dqskin.dual_quats_from_matrices(np.stack([np.eye(4, dtype=F32), matrix]))


def test_dualquat_from_matrix_without_check_takes_the_rotation():
    m = np.diag(F32([2, 3, 4, 1]))
    m[:3, 3] = [1, 2, 3]
    d = dqskin.DualQuat.from_matrix(m, check=False)
    np.testing.assert_allclose(d.real, [1, 0, 0, 0], atol=ROUNDING_TOL)
    np.testing.assert_allclose(d.translation, [1, 2, 3], atol=ROUNDING_TOL)
    # A looser tolerance accepts a slightly scaled matrix.
    dqskin.DualQuat.from_matrix(np.diag(F32([1.001, 1, 1, 1])), tolerance=1e-2)


def test_zero_dualquat_has_no_inverse_and_no_normalization():
    z = dqskin.DualQuat([0, 0, 0, 0], [1, 2, 3, 4])
    with pytest.raises(ValueError, match=r"real part is zero has no inverse"):
        z.inverse()
    with pytest.raises(ValueError, match=r"cannot normalize a dual quaternion whose real part is zero"):
        z.normalized()


@pytest.mark.parametrize(
    "make, exc, pattern",
    [
        (lambda: dqskin.DualQuat([1, 0, 0]), ValueError, r"real must have shape \(4,\)"),
        (lambda: dqskin.DualQuat([1, 0, 0, 0], [0, 0, 0, np.nan]), ValueError, r"dual contains a NaN"),
        (lambda: dqskin.DualQuat.from_rotation_translation([0, 0, 0, 0]), ValueError, r"rotation must be a non-zero quaternion"),
        (lambda: dqskin.DualQuat.from_rotation_translation([1, 0, 0, 0], [1, 2]), ValueError, r"translation must have shape \(3,\)"),
        (lambda: dqskin.DualQuat.from_translation([np.inf, 0, 0]), ValueError, r"translation contains a NaN or infinite"),
        (lambda: dqskin.DualQuat.identity().transform_point([1, 2]), ValueError, r"point must have shape \(3,\)"),
        (lambda: dqskin.DualQuat.identity().transform_points(np.zeros((4, 3))), TypeError, r"points must have dtype float32"),
        (lambda: dqskin.DualQuat.identity().transform_points(np.zeros((4, 2), F32)), ValueError, r"points must have shape \(N, 3\)"),
        (lambda: dqskin.matrices_from_dual_quats(np.zeros((2, 8), F32)), ValueError, r"dual_quats\[0\] has a zero real part"),
        (lambda: dqskin.matrices_from_dual_quats(np.zeros((2, 8))), TypeError, r"dual_quats must have dtype float32"),
        (lambda: dqskin.matrices_from_dual_quats(np.zeros((2, 4), F32)), ValueError, r"dual_quats must have shape \(N, 8\)"),
        (lambda: dqskin.dual_quats_from_matrices(np.zeros((2, 4, 4))), TypeError, r"matrices must have dtype float32"),
        (lambda: dqskin.dual_quats_from_matrices(np.eye(4, dtype=F32)), ValueError, r"matrices must have shape \(N, 4, 4\)"),
    ],
    ids=[
        "real-shape",
        "dual-nan",
        "zero-rotation",
        "translation-shape",
        "translation-inf",
        "point-shape",
        "points-float64",
        "points-shape",
        "zero-dq-to-matrix",
        "dqs-float64",
        "dqs-shape",
        "matrices-float64",
        "matrices-2d",
    ],
)
def test_dualquat_and_conversions_reject(make, exc, pattern):
    with pytest.raises(exc, match=pattern):
        make()


def test_dualquat_multiplication_with_other_types_is_a_type_error():
    with pytest.raises(TypeError):
        dqskin.DualQuat.identity() * "x"
    with pytest.raises(TypeError):
        dqskin.DualQuat.identity() + 1.0


# ---------------------------------------------------------------------------------------------
# Threads, rigs, panics


@pytest.mark.parametrize("n", [0, -1])
def test_set_num_threads_rejects_less_than_one(n):
    before = dqskin.get_num_threads()
    with pytest.raises(ValueError, match=r"threads"):
        dqskin.set_num_threads(n)
    assert dqskin.get_num_threads() == before


def test_twist_cylinder_rejects_bad_sizes():
    with pytest.raises(ValueError, match=r"rings must be between 2 and"):
        dqskin.TwistCylinder(rings=1)
    with pytest.raises(ValueError, match=r"radius must be positive"):
        dqskin.TwistCylinder(radius=-1.0)
    with pytest.raises(ValueError, match=r"r must be between 0 and 32"):
        dqskin.TwistCylinder().ring(33)


def test_mesh_measurements_reject_bad_input():
    cyl = dqskin.TwistCylinder(rings=3, segments=4)
    tris = cyl.triangles.astype(np.int64)
    tris[0, 0] = len(cyl.positions)
    with pytest.raises(ValueError, match=r"triangles\[0\] refers to vertex 14, but there are 14 positions"):
        dqskin.mesh_volume(cyl.positions, tris)
    with pytest.raises(ValueError, match=r"triangles must have shape \(T, 3\)"):
        dqskin.mesh_volume(cyl.positions, cyl.triangles[:, :2])
    with pytest.raises(TypeError, match=r"positions must have dtype float32"):
        dqskin.mesh_volume(cyl.positions.astype(np.float64), cyl.triangles)
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        dqskin.polygon_area(np.zeros((4, 2), F32))


def test_a_rust_panic_is_a_runtime_error_not_a_panic_exception():
    with pytest.raises(BaseException) as info:
        dqskin._panic_for_tests()
    exc = info.value
    # pyo3's PanicException derives from BaseException, so `except Exception` would miss it.
    assert isinstance(exc, Exception), type(exc).__mro__
    assert type(exc).__name__ != "PanicException"
    assert isinstance(exc, RuntimeError)
    assert "internal error in dqskin" in str(exc) and "deliberate panic" in str(exc)
    # The module still works afterwards.
    assert dqskin.DualQuat.identity().is_unit()


def test_rest_is_a_required_argument_that_only_linear_may_leave_none():
    a = valid()
    # The defaults do not skin (Dual Quaternion needs the rest matrices): the signature says so.
    with pytest.raises(TypeError, match=r"missing 1 required positional argument: 'rest'"):
        dqskin.skin(a["positions"], a["influences"], a["deform"])
    with pytest.raises(TypeError, match=r"missing 1 required positional argument: 'rest'"):
        dqskin.SkinJob(a["positions"], a["influences"], a["deform"])
    with pytest.raises(ValueError, match=r"rest is required for method='dual_quaternion'.*only method='linear' takes rest=None"):
        dqskin.skin(a["positions"], a["influences"], a["deform"], None)
    linear = dqskin.skin(a["positions"], a["influences"], a["deform"], None, method="linear")
    np.testing.assert_array_equal(linear, call(a, method="linear"))
    np.testing.assert_array_equal(dqskin.skin(a["positions"], a["influences"], a["deform"], a["rest"]), call(a, method="dual_quaternion"))


def _float64_calls():
    """(name, call with float64 arrays, the same call with float32) for every public function that
    takes a large array; small inputs (one matrix, a few keys) are converted."""
    a = valid()
    p, infl, d, r = a["positions"], a["influences"], a["deform"], a["rest"]
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    return [
        ("skin positions", lambda t: dqskin.skin(p.astype(t), infl, d, r)),
        ("skin deform", lambda t: dqskin.skin(p, infl, d.astype(t), r)),
        ("skin rest", lambda t: dqskin.skin(p, infl, d, r.astype(t))),
        ("skin mask", lambda t: dqskin.skin(p, infl, d, r, mask=np.ones(V, t))),
        ("SkinJob positions", lambda t: dqskin.SkinJob(p.astype(t), infl, d, r).out),
        ("Influences weights", lambda t: dqskin.Influences(infl.offsets, infl.bones, infl.weights.astype(t), B).weights),
        ("Influences.from_dense", lambda t: dqskin.Influences.from_dense(np.zeros((V, 1), int), np.ones((V, 1), t), 1).weights),
        ("centers_of_rotation", lambda t: dqskin.centers_of_rotation(p.astype(t), tri, infl)),
        ("mesh_volume", lambda t: dqskin.mesh_volume(p.astype(t), tri)),
        ("polygon_area", lambda t: dqskin.polygon_area(p[:3].astype(t))),
        ("transform_points", lambda t: dqskin.transform_points(np.eye(4), p.astype(t))),
        ("dual_quats_from_matrices", lambda t: dqskin.dual_quats_from_matrices(r.astype(t))),
        ("DualQuat.transform_points", lambda t: dqskin.DualQuat.identity().transform_points(p.astype(t))),
        (
            "sclerp (small: converted)",
            lambda t: dqskin.sclerp(np.array([1, 0, 0, 0, 0, 0, 0, 0], t), np.array([1, 0, 0, 0, 0, 0.5, 0, 0], t), 0.5),
        ),
        ("skin premat (small: converted)", lambda t: dqskin.skin(p, infl, d, r, premat=np.eye(4, dtype=t))),
    ]


@pytest.mark.parametrize("index", range(len(_float64_calls())), ids=[c[0] for c in _float64_calls()])
def test_float64_is_refused_with_a_message_that_says_so_or_converted(index):
    name, run = _float64_calls()[index]
    try:
        got = run(np.float64)
    except TypeError as e:
        message = str(e)
        assert "must have dtype float32, got float64" in message and "np.asarray(" in message, message
        return
    # Converted: the same result as with float32 input, returned as float32.
    want = run(np.float32)
    assert getattr(got, "dtype", np.dtype(np.float32)) == np.float32, name
    np.testing.assert_array_equal(got, want)
