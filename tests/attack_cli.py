# ruff: noqa: E501, E731  (a table of attacks, one per line)
"""Attack harness: run the real console script on bad inputs of every kind and classify each outcome
(exit 0 or 2, no traceback, no internal error, one error line, no temporary file, no NaN or bare null in what
it wrote, an answer within the timeout).

    .venv/bin/python tests/attack_cli.py [--base DIR] [NAME_FILTER ...]

The valid inputs (virtual subjects in TRC, C3D and MOT, a trials file, a model) are made under --base (default
a folder in the system's temporary directory) on first use. Not collected by pytest (make test runs
tests/cli/test_fuzz.py and tests/test_validation.py).
"""

import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

R = str(Path(sys.executable).with_name("reachirl"))
BASE = Path(tempfile.gettempdir()) / "reachirl-attacks"
W = BASE / "work"
MK = "shoulder=SHO,elbow=ELB,wrist=WRI,fingertip=FTP"
REPO = Path(__file__).resolve().parents[1]


def make_base():
    """Valid inputs: 1 virtual subject x 3 trials x 5 postures (TRC), 1 trial each in C3D and MOT."""
    BASE.mkdir(parents=True, exist_ok=True)
    if (BASE / "model.json").is_file():
        return
    run = lambda *a: subprocess.run([R, *a], check=True, capture_output=True, cwd=BASE)
    run("synth", "--out", "syn", "--subjects", "1", "--trials", "3", "--seed", "1")
    run("synth", "--out", "sync3d", "--subjects", "1", "--trials", "1", "--format", "c3d")
    run("synth", "--out", "synmot", "--subjects", "1", "--trials", "1", "--format", "mot")
    run(
        "preprocess",
        "--manifest",
        "syn/manifest.csv",
        "--subject-info",
        "syn/subjects.csv",
        "--markers",
        MK,
        "--out",
        "t.npz",
    )
    from reachirl.data.trial import load_trials, save_trials

    save_trials(BASE / "t3.npz", load_trials(BASE / "t.npz")[:3])
    run("fit", "t.npz", "--sections", "2", "--nodes", "30", "--max-iter", "2", "--out", "model.json")


def setup():
    if W.exists():
        shutil.rmtree(W)
    W.mkdir()
    (W / "adir").mkdir()
    (W / "afile").write_text("x")


def model(**kw):
    m = json.loads((BASE / "model.json").read_text())
    m.update(kw)
    return m


def wmodel(name, obj=None, text=None):
    p = W / name
    p.write_text(text if text is not None else json.dumps(obj))
    return str(p)


def npz_mut(name, fn):
    src = BASE / "t3.npz"
    with zipfile.ZipFile(src) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    entries = fn(entries)
    p = W / name
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as z:
        for n, b in entries.items():
            z.writestr(n, b)
    return str(p)


def meta_mut(f):
    def fn(e):
        arr = np.load(io.BytesIO(e["meta.json.npy"]))
        meta = json.loads(bytes(arr).decode())
        meta = f(meta)
        b = io.BytesIO()
        np.save(b, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
        e["meta.json.npy"] = b.getvalue()
        return e

    return fn


def arr_mut(key, f):
    def fn(e):
        a = np.load(io.BytesIO(e[key]))
        a = f(a)
        b = io.BytesIO()
        np.save(b, a)
        e[key] = b.getvalue()
        return e

    return fn


def huge_header(e):
    hdr = b"\x93NUMPY\x01\x00"
    d = "{'descr': '<f8', 'fortran_order': False, 'shape': (200000000000, 2), }"
    d = d + " " * (118 - len(d)) + "\n"
    e["0/q.npy"] = hdr + len(d).to_bytes(2, "little") + d.encode() + b"\0" * 64
    return e


def flip(name):
    b = bytearray((BASE / "t3.npz").read_bytes())
    b[len(b) // 3] ^= 0x10
    p = W / name
    p.write_bytes(bytes(b))
    return str(p)


def trunc(src, name, frac=0.6):
    b = Path(src).read_bytes()
    p = W / name
    p.write_bytes(b[: int(len(b) * frac)])
    return str(p)


def attacks():
    T = str(BASE / "t3.npz")
    M = str(BASE / "model.json")
    fit = lambda *a: [R, "fit", T, "--sections", "2", "--nodes", "30", "--max-iter", "2", *a]
    ev = lambda m, t=T, *a: [R, "evaluate", "--model", m, t, "--out", str(W / "m.json"), *a]
    sim = lambda *a: [R, "simulate", "--model", M, T, "--trial", "0", *a]
    trc = str(BASE / "syn/S01_P1_T01.trc")
    pre = lambda *a: [R, "preprocess", *a, "--markers", MK, "--out", str(W / "p.npz")]
    long = "x" * 300
    A = {}
    # ---- output paths
    for cmd, mk in [
        ("fit", lambda o: fit("--out", o)),
        ("evaluate", lambda o: [R, "evaluate", "--model", M, T, "--out", o]),
        ("simulate", lambda o: sim("--out", o)),
        ("preprocess", lambda o: [R, "preprocess", trc, "--markers", MK, "--out", o]),
        ("synth", lambda o: [R, "synth", "--subjects", "1", "--trials", "1", "--out", o + "_d"]),
    ]:
        A[f"{cmd}:out-ro"] = lambda mk=mk: mk("/proc/x.json")
        A[f"{cmd}:out-under-file"] = lambda mk=mk: mk(str(W / "afile" / "x.json"))
        A[f"{cmd}:out-is-dir"] = lambda mk=mk: mk(str(W / "adir"))
        A[f"{cmd}:out-longname"] = lambda mk=mk: mk(str(W / (long + ".json")))
    A["simulate:render-under-file"] = lambda: sim("--render", str(W / "afile/x.gif"))
    A["simulate:render-longname"] = lambda: sim("--render", str(W / (long + ".gif")))
    A["reproduce:out-under-file"] = lambda: [R, "reproduce", "--quick", "--data", T, "--out", str(W / "afile/o")]
    A["reproduce:out-ro"] = lambda: [R, "reproduce", "--quick", "--data", T, "--out", "/proc/o"]
    A["reproduce:out-longname"] = lambda: [R, "reproduce", "--quick", "--data", T, "--out", str(W / long)]
    # ---- model JSON
    for name, obj in {
        "features-int": model(features=3),
        "features-null": model(features=None),
        "weights-zero": model(weights=[[0] * 7] * 2),
        "windows>intervals": model(n_nodes=4, weights=[[0.1] * 7] * 6),
        "n_nodes0": model(n_nodes=0),
        "n_nodes-5": model(n_nodes=-5),
        "n_nodes3": model(n_nodes=3),
        "n_nodes1e308": model(n_nodes=1e308),
        "n_nodes1e9": model(n_nodes=10**9),
        "n_nodes-str": model(n_nodes="abc"),
        "n_nodes-float": model(n_nodes=30.5),
        "n_nodes-bool": model(n_nodes=True),
        "weights-neg": model(weights=[[-1] * 7] * 2),
        "weights-str": model(weights=[["a"] * 7] * 2),
        "weights-ragged": model(weights=[[1] * 7, [1] * 3]),
        "weights-null": model(weights=None),
        "weights-3d": model(weights=[[[1] * 7]]),
        "weights-empty": model(weights=[]),
        "info-list": model(info=[1, 2]),
        "method-int": model(method=5),
        "list-top": [1, 2],
        "weights-1e308": model(weights=[[1e308] * 7] * 2),
    }.items():
        A[f"evaluate:model-{name}"] = lambda name=name, obj=obj: ev(wmodel(name + ".json", obj))
    A["evaluate:model-inf"] = lambda: ev(
        wmodel("inf.json", text=json.dumps(model()).replace('"n_nodes": 30', '"n_nodes": Infinity'))
    )
    A["evaluate:model-nan-weight"] = lambda: ev(
        wmodel("nanw.json", text=json.dumps(model(weights=[[0.1] * 7] * 2)).replace("0.1", "NaN", 1))
    )
    A["evaluate:model-deep"] = lambda: ev(wmodel("deep.json", text="[" * 100000 + "]" * 100000))
    A["evaluate:model-bigint"] = lambda: ev(
        wmodel("bigint.json", text=json.dumps(model()).replace('"n_nodes": 30', '"n_nodes": ' + "9" * 5000))
    )
    A["evaluate:model-binary"] = lambda: ev(wmodel("bin.json", text="\x00\x01garbage\xff"))
    A["simulate:model-n_nodes0"] = lambda: [
        R,
        "simulate",
        "--model",
        wmodel("sn0.json", model(n_nodes=0)),
        T,
        "--trial",
        "0",
    ]
    A["simulate:model-zero"] = lambda: [
        R,
        "simulate",
        "--model",
        wmodel("sz.json", model(weights=[[0] * 7] * 2)),
        T,
        "--trial",
        "0",
    ]
    A["evaluate:model-crocoddyl-1e300"] = lambda: ev(
        wmodel("c300.json", model(weights=[[1e300] * 7] * 2)), T, "--backend", "crocoddyl"
    )
    A["evaluate:model-casadi-1e300"] = lambda: ev(wmodel("k300.json", model(weights=[[1e300] * 7] * 2)))
    # ---- trials NPZ
    A["fit:npz-flipbit"] = lambda: (
        fit("--out", str(W / "o.json"))
        and [
            R,
            "fit",
            flip("flip.npz"),
            "--sections",
            "1",
            "--nodes",
            "30",
            "--max-iter",
            "1",
            "--out",
            str(W / "o.json"),
        ]
    )
    A["evaluate:npz-flipbit"] = lambda: ev(M, flip("flip2.npz"))
    A["evaluate:npz-truncated"] = lambda: ev(M, trunc(T, "tr.npz"))
    A["evaluate:npz-meta-list"] = lambda: ev(M, npz_mut("ml.npz", meta_mut(lambda m: [m])))
    A["evaluate:npz-meta-trials-dict"] = lambda: ev(
        M, npz_mut("mtd.npz", meta_mut(lambda m: {**m, "trials": {"a": 1}}))
    )
    A["evaluate:npz-meta-trial-int"] = lambda: ev(M, npz_mut("mti.npz", meta_mut(lambda m: {**m, "trials": [5, 6, 7]})))
    A["evaluate:npz-meta-subject-list"] = lambda: ev(
        M, npz_mut("msl.npz", meta_mut(lambda m: {**m, "trials": [{**t, "subject": [1]} for t in m["trials"]]}))
    )
    A["evaluate:npz-meta-arm-list"] = lambda: ev(
        M, npz_mut("mal.npz", meta_mut(lambda m: {**m, "trials": [{**t, "arm": [1]} for t in m["trials"]]}))
    )
    A["evaluate:npz-meta-target-str"] = lambda: ev(
        M, npz_mut("mts.npz", meta_mut(lambda m: {**m, "trials": [{**t, "target_x": "x"} for t in m["trials"]]}))
    )
    A["evaluate:npz-arm-250km"] = lambda: ev(
        M,
        npz_mut(
            "a250.npz",
            meta_mut(lambda m: {**m, "trials": [{**t, "arm": {**t["arm"], "l1": 250e3}} for t in m["trials"]]}),
        ),
    )
    A["evaluate:npz-arm-mass-neg"] = lambda: ev(
        M,
        npz_mut(
            "amn.npz", meta_mut(lambda m: {**m, "trials": [{**t, "arm": {**t["arm"], "m1": -2}} for t in m["trials"]]})
        ),
    )
    A["evaluate:npz-huge-shape"] = lambda: ev(M, npz_mut("hs.npz", huge_header))
    A["evaluate:npz-q0-outside"] = lambda: ev(
        M, npz_mut("q0o.npz", arr_mut("0/x0.npy", lambda a: np.array([3.0, 3.0, 0, 0])))
    )
    A["evaluate:npz-q-object"] = lambda: ev(
        M,
        npz_mut(
            "qo.npz",
            lambda e: {
                **e,
                "0/q.npy": b"\x93NUMPY\x01\x00v\x00{'descr': '|O', 'fortran_order': False, 'shape': (3,), }"
                + b" " * 50
                + b"\n",
            },
        ),
    )
    A["evaluate:npz-duration-1us"] = lambda: ev(M, npz_mut("dur.npz", arr_mut("0/t.npy", lambda a: a * 1e-6)))
    A["evaluate:npz-duration-1e6"] = lambda: ev(M, npz_mut("durl.npz", arr_mut("0/t.npy", lambda a: a * 1e6)))
    A["fit:npz-q0-outside"] = lambda: [
        R,
        "fit",
        npz_mut("q0o2.npz", arr_mut("0/x0.npy", lambda a: np.array([3.0, 3.0, 0, 0]))),
        "--sections",
        "1",
        "--nodes",
        "30",
        "--max-iter",
        "1",
        "--out",
        str(W / "o.json"),
    ]
    A["simulate:npz-arm-250km"] = lambda: [
        R,
        "simulate",
        "--model",
        M,
        npz_mut(
            "a250b.npz",
            meta_mut(lambda m: {**m, "trials": [{**t, "arm": {**t["arm"], "l1": 250e3}} for t in m["trials"]]}),
        ),
        "--trial",
        "0",
    ]
    # ---- options
    A["fit:nodes3"] = lambda: [R, "fit", T, "--sections", "1", "--nodes", "3", "--out", str(W / "o.json")]
    A["fit:nodes-huge"] = lambda: [R, "fit", T, "--sections", "1", "--nodes", "100000000", "--out", str(W / "o.json")]
    A["fit:max-iter0"] = lambda: fit("--max-iter", "0", "--out", str(W / "o.json"))
    A["fit:max-iter-1"] = lambda: fit("--max-iter", "-1", "--out", str(W / "o.json"))
    A["fit:sections0"] = lambda: [R, "fit", T, "--sections", "0", "--nodes", "30", "--out", str(W / "o.json")]
    A["fit:sections-huge"] = lambda: [R, "fit", T, "--sections", "999999", "--nodes", "30", "--out", str(W / "o.json")]
    A["fit:bilevel"] = lambda: [
        R,
        "fit",
        T,
        "--sections",
        "1",
        "--nodes",
        "30",
        "--method",
        "bilevel",
        "--out",
        str(W / "o.json"),
    ]
    A["preprocess:cutoff-nan"] = lambda: pre(trc, "--cutoff", "nan")
    A["preprocess:cutoff-inf"] = lambda: pre(trc, "--cutoff", "inf")
    A["preprocess:cutoff-neg"] = lambda: pre(trc, "--cutoff", "-3")
    A["preprocess:cutoff-above-nyquist"] = lambda: pre(trc, "--cutoff", "1000")
    A["preprocess:filter-order-1"] = lambda: pre(trc, "--filter-order", "-1")
    A["preprocess:filter-order0"] = lambda: pre(trc, "--filter-order", "0")
    A["preprocess:filter-order-huge"] = lambda: pre(trc, "--filter-order", "1000")
    A["preprocess:threshold-nan"] = lambda: pre(trc, "--threshold", "nan")
    A["preprocess:n-samples0"] = lambda: pre(trc, "--n-samples", "0")
    A["preprocess:n-samples-huge"] = lambda: pre(trc, "--n-samples", "1000000000")
    A["preprocess:max-gap-neg"] = lambda: pre(trc, "--max-gap", "-1")
    for v in ("0", "-1", "nan", "inf", "1e9"):
        A[f"simulate:fps{v}"] = lambda v=v: sim("--fps", v, "--render", str(W / "r.gif"))
    for v in ("0", "-1", "100000"):
        A[f"simulate:size{v}"] = lambda v=v: sim("--size", v, "--render", str(W / "r.gif"))
    for v in ("nan", "inf", "-5"):
        A[f"simulate:kp{v}"] = lambda v=v: sim("--mode", "pd", "--kp", v)
        A[f"simulate:kd{v}"] = lambda v=v: sim("--mode", "pd", "--kd", v)
    A["simulate:substeps-huge"] = lambda: sim("--substeps", "1000000000")

    # ---- CSV inputs
    def garbage(name):
        p = W / name
        p.write_bytes(b'a"b,c\rd\x00e\n"x\r\n,,,\xff\xfe"')
        return str(p)

    def garbage_text(name):
        p = W / name
        p.write_bytes(b'subject,sex\r"x\ry,1\n"unclosed,\xe9\n,,,,\n')
        return str(p)

    A["preprocess:subject-info-garbage-text"] = lambda: pre(trc, "--subject-info", garbage_text("si2.csv"))
    A["preprocess:manifest-garbage-text"] = lambda: [
        R,
        "preprocess",
        "--manifest",
        garbage_text("man2.csv"),
        "--markers",
        MK,
        "--out",
        str(W / "p.npz"),
    ]
    A["simulate:render-too-many-frames"] = lambda: [
        R,
        "simulate",
        "--model",
        M,
        T,
        "--fps",
        "120",
        "--size",
        "1280",
        "--render",
        str(W / "big.gif"),
    ]
    A["bench:out-under-file"] = lambda: [R, "bench", "doc", "--quick", "--out", str(W / "afile/b.json")]
    A["evaluate:model-tiny-uniform"] = lambda: ev(wmodel("tiny.json", model(weights=[[1e-16] * 7] * 2)))
    A["preprocess:subject-info-garbage"] = lambda: pre(trc, "--subject-info", garbage("si.csv"))
    A["preprocess:manifest-garbage"] = lambda: [
        R,
        "preprocess",
        "--manifest",
        garbage("man.csv"),
        "--markers",
        MK,
        "--out",
        str(W / "p.npz"),
    ]

    def data_dir(truth_text):
        d = W / f"dd{abs(hash(truth_text)) % 10000}"
        shutil.copytree(BASE / "syn", d)
        (d / "truth.json").write_text(truth_text)
        return str(d)

    A["reproduce:data-truth-malformed"] = lambda: [
        R,
        "reproduce",
        "--quick",
        "--data",
        data_dir("{bad"),
        "--markers",
        MK,
        "--out",
        str(W / "ro1"),
        "--workers",
        "1",
        "--max-iter",
        "1",
        "--nodes",
        "20",
    ]
    A["reproduce:data-truth-list"] = lambda: [
        R,
        "reproduce",
        "--quick",
        "--data",
        data_dir("[1,2]"),
        "--markers",
        MK,
        "--out",
        str(W / "ro2"),
        "--workers",
        "1",
        "--max-iter",
        "1",
        "--nodes",
        "20",
    ]

    # ---- preprocess inputs
    def mktrc(name, f):
        lines = Path(trc).read_text().splitlines()
        lines = f(lines)
        p = W / name
        p.write_text("\n".join(lines) + "\n")
        return str(p)

    A["preprocess:trc-devzero"] = lambda: pre("/dev/zero", "--format", "trc")
    A["preprocess:trc-devzero-auto"] = lambda: pre("/dev/zero")
    A["preprocess:trc-rate0"] = lambda: pre(
        mktrc("r0.trc", lambda L: [*L[:2], "0.00\t0.00" + L[2][L[2].index("\t", 7) :], *L[3:]])
    )

    def big(L):
        return L[:6] + ["\t".join(x if i < 2 else "1e308" for i, x in enumerate(l.split("\t"))) for l in L[6:]]

    A["preprocess:trc-1e308"] = lambda: pre(mktrc("big.trc", big))

    def cell(L, col, f):
        L = list(L)
        p = L[60].split("\t")
        p[col] = f(p[col])
        L[60] = "\t".join(p)
        return L

    A["preprocess:trc-one-cell-1e308"] = lambda: pre(mktrc("c308.trc", lambda L: cell(L, 5, lambda v: "1e308")))
    A["preprocess:trc-marker-spike-500mm"] = lambda: pre(
        mktrc("spk.trc", lambda L: cell(L, 11, lambda v: str(float(v) + 500)))
    )
    A["preprocess:trc-swapped"] = lambda: [
        R,
        "preprocess",
        trc,
        "--markers",
        "shoulder=FTP,elbow=WRI,wrist=ELB,fingertip=SHO",
        "--out",
        str(W / "p.npz"),
    ]
    A["preprocess:trc-truncated"] = lambda: pre(trunc(trc, "tt.trc", 0.05))
    A["preprocess:trc-binary"] = lambda: pre(trunc(sys.executable, "bb.trc", 0.001))
    c3d = str(BASE / "sync3d/S01_P1_T01.c3d")
    A["preprocess:c3d-truncated"] = lambda: pre(trunc(c3d, "t.c3d", 0.6))
    A["preprocess:c3d-truncated-small"] = lambda: pre(trunc(c3d, "t2.c3d", 0.1))
    A["preprocess:c3d-devzero"] = lambda: pre("/dev/zero", "--format", "c3d")
    A["preprocess:c3d-flipbit"] = lambda: pre(flipf(c3d, "f.c3d"))
    mot = str(BASE / "synmot/S01_P1_T01.mot")
    A["preprocess:mot-5rows"] = lambda: [
        R,
        "preprocess",
        mktrc2(mot, "m5.mot", lambda L: L[: 7 + 5]),
        "--out",
        str(W / "p.npz"),
    ]

    def spike(L):
        i = 7 + 50
        parts = L[i].split("\t")
        parts[1] = str(float(parts[1]) + 359)
        L[i] = "\t".join(parts)
        return L

    A["preprocess:mot-spike359"] = lambda: [R, "preprocess", mktrc2(mot, "sp.mot", spike), "--out", str(W / "p.npz")]
    A["preprocess:mot-devzero"] = lambda: [R, "preprocess", "/dev/zero", "--format", "mot", "--out", str(W / "p.npz")]
    vcsv = str(REPO / "src/reachirl/data/ue_adl_sample/ADL001/ADL001FL1.csv")
    A["preprocess:vicon-truncated"] = lambda: [
        R,
        "preprocess",
        trunc(vcsv, "ADL001FL9.csv", 0.05),
        "--markerset",
        "ue-adl",
        "--out",
        str(W / "p.npz"),
    ]
    # ---- reproduce
    RQ0 = lambda o, *a: [
        R,
        "reproduce",
        "--quick",
        "--data",
        T,
        "--workers",
        "1",
        "--nodes",
        "20",
        "--out",
        str(W / o),
        *a,
    ]
    RQ = lambda o, *a: RQ0(o, "--max-iter", "1", *a)
    # without --max-iter: a run of bilevel alone refuses it (its max_iter is MO-IRL's and MaxEnt's)
    A["reproduce:bilevel"] = lambda: RQ0("rb", "--method", "bilevel", "--sections", "1")
    A["reproduce:scheduler-bad"] = lambda: RQ("rs", "--scheduler", "foo://bar:1")
    A["reproduce:scheduler-closed"] = lambda: RQ("rs2", "--scheduler", "tcp://127.0.0.1:1")
    A["reproduce:one-trial"] = lambda: [
        R,
        "reproduce",
        "--quick",
        "--data",
        one_trial(),
        "--workers",
        "1",
        "--nodes",
        "20",
        "--max-iter",
        "1",
        "--sections",
        "1",
        "--out",
        str(W / "r1"),
    ]
    A["reproduce:n-train-big"] = lambda: RQ("rn", "--n-train", "1000", "--sections", "1")
    A["reproduce:cv-other-side"] = lambda: RQ("rc", "--cv", "other-side", "--sections", "1")
    A["reproduce:nodes-huge"] = lambda: [
        R,
        "reproduce",
        "--quick",
        "--data",
        T,
        "--workers",
        "1",
        "--nodes",
        "100000000",
        "--out",
        str(W / "rh"),
    ]
    A["reproduce:method-bogus"] = lambda: RQ("rm", "--method", "bogus")
    A["reproduce:sections-huge"] = lambda: RQ("rsh", "--sections", "500")
    A["reproduce:data-missing"] = lambda: [R, "reproduce", "--quick", "--data", str(W / "nope"), "--out", str(W / "rx")]

    # ---- issue 34: outputs over inputs, FIFOs, truncated recordings, inconsistent inputs (tests/cli/test_nothing_lost*.py)
    def victim(src, name):
        p = W / name
        shutil.copy(src, p)
        return str(p)

    def fifo(name):
        p = W / name
        if not p.exists():
            os.mkfifo(p)
        return str(p)

    A["preprocess:out-is-recording"] = lambda: (lambda v: [R, "preprocess", v, "--markers", MK, "--out", v])(
        victim(trc, "v.trc")
    )
    A["fit:out-is-trials"] = lambda: (lambda v: [R, "fit", v, "--sections", "1", "--nodes", "30", "--out", v])(
        victim(T, "v.npz")
    )
    A["evaluate:out-is-model"] = lambda: (lambda v: [R, "evaluate", "--model", v, T, "--out", v])(victim(M, "v.json"))
    A["evaluate:predictions-under-file"] = lambda: ev(M, T, "--predictions", str(W / "afile" / "p"))
    A["preprocess:fifo"] = lambda: pre(fifo("f.trc"))
    A["evaluate:fifo-trials"] = lambda: ev(M, fifo("f.npz"))
    A["preprocess:mot-cut-at-row"] = lambda: [
        R,
        "preprocess",
        mktrc2(mot, "cut.mot", lambda L: L[:100]),
        "--out",
        str(W / "p.npz"),
    ]
    A["preprocess:mot-nrows-huge"] = lambda: [
        R,
        "preprocess",
        mktrc2(mot, "nr.mot", lambda L: ["nRows=999999999" if x.startswith("nRows") else x for x in L]),
        "--out",
        str(W / "p.npz"),
    ]
    A["preprocess:trc-cut-at-row"] = lambda: pre(mktrc("cut.trc", lambda L: L[:90]))
    A["simulate:pd-gains-huge"] = lambda: sim("--mode", "pd", "--kp", "100000", "--kd", "10000")
    A["evaluate:npz-target-negative"] = lambda: ev(
        M, npz_mut("tneg.npz", meta_mut(lambda m: {**m, "trials": [{**t, "target_x": -0.3} for t in m["trials"]]}))
    )
    A["evaluate:npz-target-zero"] = lambda: ev(
        M, npz_mut("tzero.npz", meta_mut(lambda m: {**m, "trials": [{**t, "target_x": 0.0} for t in m["trials"]]}))
    )
    A["evaluate:npz-start-velocity-1e6"] = lambda: ev(
        M, npz_mut("qd0.npz", arr_mut("0/x0.npy", lambda a: np.r_[a[:2], 1e6, 0.0]))
    )
    A["evaluate:model-rollout-1e6"] = lambda: ev(
        wmodel("ro.json", model(info={**model()["info"], "rollout_q": [[1e6, 1.0]] * 31}))
    )
    A["sensitivity:workers-huge"] = lambda: [R, "sensitivity", str(W), "--out", str(W / "s"), "--workers", "10000"]
    A["reproduce:subjects-huge"] = lambda: [R, "reproduce", "--quick", "--subjects", "100000", "--out", str(W / "rsub")]
    return A


def flipf(src, name):
    b = bytearray(Path(src).read_bytes())
    for i in range(len(b) // 2, len(b) // 2 + 40):
        b[i] ^= 0xFF
    p = W / name
    p.write_bytes(bytes(b))
    return str(p)


def mktrc2(src, name, f):
    L = Path(src).read_text().splitlines()
    L = f(L)
    p = W / name
    p.write_text("\n".join(L) + "\n")
    return str(p)


def one_trial():
    from reachirl.data.trial import load_trials, save_trials

    p = W / "one.npz"
    save_trials(p, load_trials(BASE / "t3.npz")[:1])
    return str(p)


EXPECT_NUMBER = {"mean", "std", "q", "q1", "q2", "merit", "rmse", "cost", "summary"}


def bad_values(obj, path=""):
    """NaN/infinity anywhere; null where a number is expected without a "no_data" reason beside it."""
    out = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            if (isinstance(v, float) and v != v) or v in (float("inf"), float("-inf")):
                out.append(f"{path}/{k}")
            elif v is None and k in EXPECT_NUMBER and "no_data" not in obj:
                out.append(f"{path}/{k}")
            else:
                out += bad_values(v, f"{path}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += bad_values(v, f"{path}/{i}")
    elif isinstance(obj, float) and (obj != obj or obj in (float("inf"), float("-inf"))):
        out.append(path)
    return out


def nan_in(path):
    txt = path.read_text(errors="replace")
    if path.suffix == ".json":
        try:
            return bool(bad_values(json.loads(txt)))
        except json.JSONDecodeError:
            return True  # a half-written JSON
    return bool(re.search(r"(?<![A-Za-z])(nan|NaN|inf|Infinity)(?![A-Za-z])", txt))


def run(names=None, timeout=60):
    setup()
    A = attacks()
    bad = []
    counts = {}
    for name, mk in A.items():
        if names and not any(n in name for n in names):
            continue
        argv = mk()
        before = set(p for p in W.rglob("*"))
        t0 = time.time()
        try:
            p = subprocess.run(
                argv,
                capture_output=True,
                text=True,
                timeout=timeout,
                cwd=W,
                env={**os.environ, "MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": "osmesa"},
            )
            rc, err = p.returncode, p.stderr
        except subprocess.TimeoutExpired as e:
            rc, err = (
                "TIMEOUT",
                (e.stderr or b"").decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or ""),
            )
        dt = time.time() - t0
        after = set(W.rglob("*"))
        new = after - before
        tmp = [str(x) for x in new if x.name.startswith(".") or x.name.endswith(".tmp")]
        nans = [str(x) for x in new if x.is_file() and x.suffix in (".json", ".csv", ".md") and nan_in(x)]
        errlines = [l for l in err.strip().splitlines() if l.strip()]
        ok = rc in (0, 2) and "Traceback" not in err and "internal error" not in err and not tmp and not nans
        if rc == 2 and (not errlines or ": error:" not in errlines[-1] or sum(": error" in l for l in errlines) > 1):
            ok = False
        cmd = name.split(":")[0]
        c = counts.setdefault(cmd, [0, 0])
        c[0] += 1
        c[1] += ok
        tag = "OK " if ok else "BAD"
        last = errlines[-1][:200] if errlines else ""
        print(
            f"{tag} {name:40s} rc={rc} {dt:5.1f}s {last}"
            + (f" TMP={tmp}" if tmp else "")
            + (f" NAN={nans}" if nans else ""),
            flush=True,
        )
        if not ok:
            bad.append(name)
    print("counts:", counts)
    print("bad:", bad)


def main(argv=None):
    global BASE, W
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--base"]:
        BASE = Path(argv[1]).resolve()
        W = BASE / "work"
        argv = argv[2:]
    make_base()
    run(argv or None, timeout=60)


if __name__ == "__main__":
    main()
