"""Property-based tests of every reader: any input ends in a valid object or in ringfit's InputError.

Inputs are built near the valid ones (known keys and columns, typos of
them, numbers at the edges of float64, huge integers, NaN, deep nesting,
long cells) and, for binary formats, valid files cut or with bytes flipped —
where a reader that is not careful fails with something other than
``InputError``. Bounded (``max_examples``, no deadline) to keep the suite fast.
"""

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ringfit.errors import InputError

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=True)


def _accepts_or_input_error(read, path):
    """The property: ``read(path)`` returns, or raises InputError with one line; nothing else."""
    try:
        return read(path)
    except InputError as exc:
        assert "\n" not in str(exc)
        return None


ROOT = None  # a temporary folder for the whole module (see _valid_files)


def _tmp(data: bytes | str, name: str) -> Path:
    d = Path(tempfile.mkdtemp(prefix="ex-", dir=ROOT))
    p = d / name
    if isinstance(data, str):
        p.write_text(data, encoding="utf-8", errors="surrogatepass")
    else:
        p.write_bytes(data)
    return p


# ----------------------------------------------------------------------------- values

EDGE_NUMBERS = st.sampled_from([0, -0.0, 1, -1, 2.2, 1e-300, 1e300, -1e300, 1e30, 10**400, -(10**400), 2**63,
                                float("nan"), float("inf"), float("-inf"), 5e-324, 1.7976931348623157e308])
NUMBER = st.one_of(EDGE_NUMBERS, st.floats(allow_nan=True, allow_infinity=True), st.integers())
CELL_TEXT = st.one_of(
    NUMBER.map(lambda x: repr(x) if not isinstance(x, int) else str(x)),
    st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "1e30", "1" + "0" * 400, "0x10", "1,5", "structural",
                     "acoustic", "extr", "backward", "forward", "vert", "x" * 131_100, "\x00", '"', "'", "é"]),
    st.text(max_size=12),
)


def _json_values():
    leaf = st.one_of(st.none(), st.booleans(), NUMBER.filter(lambda x: not isinstance(x, float) or np.isfinite(x)),
                     st.text(max_size=8))
    return st.recursive(leaf, lambda c: st.one_of(st.lists(c, max_size=3), st.dictionaries(st.text(max_size=6), c,
                                                                                            max_size=3)),
                        max_leaves=8)


# ----------------------------------------------------------------------------- tyre TOML

TYRE_KEYS = ["name", "radius_m", "width_m", "pressure_bar", "tread_thickness_m", "widht_m", "radius"]
RING_KEYS = ["rho_a_kg_per_m", "ei_n_m2", "kw_n_per_m2", "kv_n_per_m2", "damping_ratio", "k_tread_n_per_m2", "ea_n",
             "chi", "ei_nm2", "kw"]
TOML_VALUES = st.sampled_from(["0.296", "0.152", "2.2", "1e300", "-1", "0", "nan", "inf", "1" + "0" * 400, '"abc"',
                               "[1, 2]", "true", "1979-05-27", "{a = 1}", "[[[[[1]]]]]", "0x10", "2.715", "19e6"])


@st.composite
def tyre_toml(draw):
    lines = []
    for table, keys in (("tyre", TYRE_KEYS), ("ring", RING_KEYS)):
        if draw(st.booleans()) or table == "tyre":
            lines.append(f"[{draw(st.sampled_from([table, table, 'rign', 'meta']))}]")
            for key in draw(st.lists(st.sampled_from(keys), unique=True, max_size=6)):
                lines.append(f"{key} = {draw(TOML_VALUES)}")
    if draw(st.booleans()):
        lines.insert(0, draw(st.sampled_from(["ring = 5", 'tyre = "x"', "x = " + "[" * 3000 + "]" * 3000, "= 1",
                                              "[tyre", "a.b.c = 1"])))
    return "\n".join(lines) + "\n"


@FAST
@given(tyre_toml())
def test_tyre_reader(text):
    from ringfit.io.tyre import RANGES, read_tyre

    t = _accepts_or_input_error(read_tyre, _tmp(text, "t.toml"))
    if t is not None:  # what it accepts is in range
        assert 0.05 < float(t.geometry.radius) <= RANGES["radius_m"][1]
        assert all(np.isfinite(v) for v in t.ring_values.values())


# ----------------------------------------------------------------------------- mode table + sidecar

MODE_COLUMNS = ["n", "a", "tag", "kind", "freq_hz", "freq_std_hz", "damping_pct", "branch", "comment", "freq_hz"]


@st.composite
def mode_csv(draw):
    header = draw(st.lists(st.sampled_from(MODE_COLUMNS), min_size=1, max_size=6))
    rows = draw(st.lists(st.lists(CELL_TEXT, min_size=len(header), max_size=len(header) + 1), max_size=4))
    esc = lambda c: '"' + c.replace('"', '""') + '"' if ("," in c or "\n" in c or '"' in c) else c  # noqa: E731
    return "\n".join([",".join(header)] + [",".join(esc(c) for c in r) for r in rows]) + "\n"


@FAST
@given(mode_csv(), st.one_of(st.none(), _json_values(), st.sampled_from(["[" * 50000 + "]" * 50000,
                                                                         '{"load_n": ' + "9" * 400 + "}",
                                                                         '{"state": "free", "speed_kmh": 1e300}'])))
def test_mode_table_reader(text, sidecar):
    from ringfit.io.modes import MAX_FREQ_HZ, read_mode_table

    p = _tmp(text, "m.modes.csv")
    if sidecar is not None:
        (p.parent / "m.modes.json").write_text(sidecar if isinstance(sidecar, str) else json.dumps(sidecar))
    t = _accepts_or_input_error(read_mode_table, p)
    if t is not None:
        assert np.all(np.isfinite(t.freq_hz)) and np.all((t.freq_hz > 0) & (t.freq_hz <= MAX_FREQ_HZ))


# ----------------------------------------------------------------------------- profile + sidecar

PROFILE_KEYS = ["speed_kmh", "load_n", "pressure_bar", "revolutions", "sample_rate_hz", "rotation_hz",
                "drum_diameter_m"]


@st.composite
def profile_files(draw):
    m = draw(st.sampled_from([16, 17, 32]))
    angle = -180.0 + 360.0 * np.arange(m) / m
    cols = {"angle_deg": [repr(float(a)) for a in angle], "acc_radial_ms2": ["1.0"] * m,
            "acc_tangential_ms2": ["0.5"] * m}
    for _ in range(draw(st.integers(0, 3))):  # break a few cells
        c = draw(st.sampled_from(sorted(cols)))
        cols[c][draw(st.integers(0, m - 1))] = draw(CELL_TEXT)
    names = draw(st.permutations(sorted(cols)))
    text = ",".join(names) + "\n" + "\n".join(",".join(cols[c][i] for c in names) for i in range(m)) + "\n"
    side = {k: 1.0 for k in PROFILE_KEYS[:3]}
    for key in draw(st.lists(st.sampled_from(PROFILE_KEYS), max_size=4)):
        side[key] = draw(_json_values())
    return text, side


@FAST
@given(profile_files())
def test_profile_reader(files):
    from ringfit.io.profiles import read_profile

    text, side = files
    p = _tmp(text, "r.profile.csv")
    try:
        (p.parent / "r.profile.json").write_text(json.dumps(side))
    except ValueError:  # NaN keys etc. that json refuses to write: nothing to read then
        return
    prof = _accepts_or_input_error(read_profile, p)
    if prof is not None:
        assert np.all(np.isfinite(prof.channels)) and len(prof) >= 16


# ----------------------------------------------------------------------------- records npz

DTYPES = st.sampled_from([np.float64, np.float32, np.int16, np.complex128, np.bool_, "U8", object])


@st.composite
def records_arrays(draw):
    r, a, s = draw(st.integers(0, 3)), draw(st.integers(0, 3)), draw(st.integers(0, 70))
    out = {"acc": np.ones((r, a, s)), "axes": np.array(["radial", "tangential", "lateral"][:a]),
           "sensor_angle_deg": np.zeros(r), "fs_hz": np.float64(1000.0)}
    if draw(st.booleans()):
        out["force"] = np.ones((r, s))
    for key in draw(st.lists(st.sampled_from(sorted(out) + ["force"]), max_size=3)):
        shape = draw(st.lists(st.integers(0, 4), max_size=3))
        dtype = draw(DTYPES)
        value = draw(st.sampled_from([0.0, 1.0, np.nan, np.inf, 1e300, -1e300, 5e-324]))
        with np.errstate(all="ignore"):
            try:
                out[key] = np.full(shape, value).astype(dtype)
            except (ValueError, OverflowError):
                out[key] = np.full(shape, "x")
    if draw(st.booleans()):
        del out[draw(st.sampled_from(sorted(out)))]
    return out


@FAST
@given(records_arrays())
def test_records_npz_reader(arrays):
    from ringfit.io.records import read_records

    p = _tmp(b"", "r.records.npz")
    with open(p, "wb") as fh:
        np.savez(fh, **arrays)
    rec = _accepts_or_input_error(read_records, p)
    if rec is not None:
        assert np.all(np.isfinite(rec.acc)) and rec.fs_hz > 0


def _valid_bytes(kind) -> bytes:
    from ringfit.io.records import Records, write_records

    rng = np.random.default_rng(0)
    rec = Records(acc=rng.standard_normal((2, 2, 40)), axes=("radial", "tangential"),
                  sensor_angle_deg=np.array([0.0, 30.0]), fs_hz=1000.0, force=rng.standard_normal((2, 40)))
    d = Path(tempfile.mkdtemp(prefix="valid-", dir=ROOT))
    if kind == "continuous":
        from ringfit.io.continuous import ContinuousRecord, write_continuous

        t = np.arange(400) / 400.0
        c = ContinuousRecord(acc=rng.standard_normal((2, 400)), axes=("radial", "tangential"), fs_hz=400.0,
                             encoder_angle_deg=(3600 * t) % 360, hall=(np.sin(40 * t) > 0.9).astype(float))
        return write_continuous(c, d / "c.records.npz").read_bytes()
    return write_records(rec, d / ("r.uff" if kind == "uff" else "r.records.npz")).read_bytes()


def _mutate(data: bytes, cuts, flips) -> bytes:
    b = bytearray(data)
    for pos, val in flips:
        b[int(pos * (len(b) - 1))] ^= val
    if cuts is not None:
        b = b[: int(cuts * len(b))]
    return bytes(b)


MUTATIONS = (st.one_of(st.none(), st.floats(0, 1)),
             st.lists(st.tuples(st.floats(0, 1), st.integers(1, 255)), max_size=4))


@FAST
@given(*MUTATIONS)
def test_records_npz_bytes(cut, flips):
    from ringfit.io.records import read_records

    _accepts_or_input_error(read_records, _tmp(_mutate(NPZ_BYTES, cut, flips), "r.records.npz"))


@FAST
@given(*MUTATIONS)
def test_uff_bytes(cut, flips):
    from ringfit.io.records import read_measurement

    _accepts_or_input_error(read_measurement, _tmp(_mutate(UFF_BYTES, cut, flips), "r.uff"))


@FAST
@given(st.lists(st.tuples(st.integers(0, 40), st.sampled_from(["", "    -1", "    58", "x", "1e400", "-" * 90,
                                                               "         0", "nan"])), max_size=3),
       st.booleans())
def test_uff_ascii_lines(edits, drop):
    """Line-level edits of an ASCII UFF written by other software (tests/data/uff)."""
    from ringfit.io.records import read_measurement

    lines = (Path(__file__).parent / "data/uff/time-history-not-all-columns-filled.uff").read_text(
        encoding="utf-8").splitlines()
    for i, text in edits:
        i = min(i, len(lines) - 1)
        if drop:
            del lines[i]
        else:
            lines[i] = text
    _accepts_or_input_error(lambda p: read_measurement(p, axes={0: "radial"}, angles={0: 0.0}),
                            _tmp("\n".join(lines) + "\n", "e.uff"))


@FAST
@given(*MUTATIONS)
def test_continuous_bytes(cut, flips):
    from ringfit.io.continuous import read_continuous

    def read(p):
        with read_continuous(p) as rec:
            for _ in rec.chunks(128):
                pass
            return rec

    _accepts_or_input_error(read, _tmp(_mutate(CONT_BYTES, cut, flips), "c.records.npz"))


# ----------------------------------------------------------------------------- posterior

@st.composite
def posterior_parts(draw):
    k, steps, walkers = 2, 6, 4
    v1 = draw(st.booleans())  # both formats ringfit reads: /1 (problem keys at the top) and /2 (under "meta")
    problem = {"data": {"n": [1, 2], "freq_hz": [100.0, 110.0], "sigma_hz": [1.0, 1.0]},
               "geometry": {"radius": 0.3}, "priors": {}, "source": "x"}
    head = {"names": ["ei", "kw"], "values0": {"ei": 1.0}, "burn": 1, "thin": 1}
    if v1:
        head.update(problem)
    else:
        head.update(kinds=["log", "log"], centers=[0.0, 0.0], scales=[1.0, 1.0], meta=problem)
    for key in draw(st.lists(st.sampled_from(sorted(head)), max_size=3)):
        head[key] = draw(_json_values())
    if draw(st.booleans()):
        del head[draw(st.sampled_from(sorted(head)))]
    arrays = {"chain": np.zeros((steps, walkers, k)), "log_prob": np.zeros((steps, walkers)),
              "acceptance": np.zeros(walkers), "tau": np.ones(k)}
    for key in draw(st.lists(st.sampled_from(sorted(arrays)), max_size=2)):
        arrays[key] = np.zeros(draw(st.lists(st.integers(0, 3), max_size=3)))
    return ("ringfit-posterior/1" if v1 else "ringfit-posterior/2"), head, arrays


@settings(max_examples=25, deadline=None, derandomize=True)
@given(posterior_parts(), st.booleans())
def test_posterior_reader(parts, as_text):
    import h5py

    from ringfit.fit.posterior import load_posterior

    fmt, meta, arrays = parts
    p = _tmp(b"", "p.h5")
    with h5py.File(p, "w") as h5:
        h5.attrs["format"] = fmt
        h5.attrs["meta"] = "{not json" if as_text else json.dumps(meta, default=str)
        for key, value in arrays.items():
            h5.create_dataset(key, data=value)
    _accepts_or_input_error(load_posterior, p)


@pytest.fixture(scope="module", autouse=True)
def _valid_files():
    global NPZ_BYTES, UFF_BYTES, CONT_BYTES, ROOT
    with tempfile.TemporaryDirectory(prefix="ringfit-fuzz-") as root:
        ROOT = root
        NPZ_BYTES, UFF_BYTES, CONT_BYTES = _valid_bytes("npz"), _valid_bytes("uff"), _valid_bytes("continuous")
        yield
        ROOT = None
