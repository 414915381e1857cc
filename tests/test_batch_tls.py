"""The cluster on TLS and without HTTP endpoints (issue 23 item 6).

A LocalCluster started on TLS from a `--security FILE.toml` (certificates
made by `distributed.security.Security.temporary()`, written to PEM files)
runs a tiny batch; a client without the certificates, or speaking plain TCP,
is refused. The default LocalCluster opens no dashboard and its HTTP servers
(scheduler and workers) answer nothing; `dashboard=` brings the routes back,
which shows the check can fail.
"""

import sys
import urllib.error
import urllib.request

import pytest

pytest.importorskip("distributed")
pytest.importorskip("cryptography")

import cloudpickle  # noqa: E402

from ringfit.batch import Task, local_cluster, open_client, read_security, run_tasks  # noqa: E402
from ringfit.cli import main  # noqa: E402
from ringfit.data import path as data_path  # noqa: E402
from ringfit.errors import InputError  # noqa: E402

cloudpickle.register_pickle_by_value(sys.modules[__name__])


def _square(x):
    return x * x


def _security_file(folder, **extra):
    from distributed.security import Security

    tmp = Security.temporary()  # PEM text of a fresh self-signed CA, certificate and key
    (folder / "ca.pem").write_text(tmp.tls_ca_file)
    (folder / "cert.pem").write_text(tmp.tls_client_cert)
    (folder / "key.pem").write_text(tmp.tls_client_key)
    lines = ['ca_file = "ca.pem"', 'cert = "cert.pem"', 'key = "key.pem"'] + [f"{k} = {v!r}" for k, v in extra.items()]
    path = folder / "security.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _status(url):
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as exc:
        return exc.code


def _http_ports(cluster, client):
    sched = [s.getsockname()[1] for s in cluster.scheduler.http_server._sockets.values()]
    workers = client.run(lambda dask_worker: [s.getsockname()[1] for s in dask_worker.http_server._sockets.values()])
    return sched, [p for ports in workers.values() for p in ports]


@pytest.mark.parametrize("dashboard", [None, "127.0.0.1:0"])
def test_default_local_cluster_serves_no_http(dashboard):
    import distributed

    cluster = local_cluster(1, memory_limit="2GB", dashboard=dashboard)
    try:
        with distributed.Client(cluster) as client:
            sched, workers = _http_ports(cluster, client)
            assert sched and workers
            codes = {path: _status(f"http://127.0.0.1:{sched[0]}{path}") for path in ("/health", "/status", "/metrics")}
            worker_health = _status(f"http://127.0.0.1:{workers[0]}/health")
            if dashboard is None:
                assert set(codes.values()) == {404} and worker_health == 404
            else:  # the same check sees the routes when a dashboard is asked for
                assert codes["/health"] == 200
    finally:
        cluster.close()


def test_tls_local_cluster_runs_a_tiny_batch(tmp_path):
    sec = read_security(_security_file(tmp_path))
    assert sec.require_encryption
    with open_client(None, 1, memory_limit="2GB", security=sec) as client:
        address = client.scheduler.address
        assert address.startswith("tls://")
        results = run_tasks(client, [Task(f"x{i}", _square, (i,)) for i in range(3)], progress=False)
        assert [r.value for r in results] == [0, 1, 4] and all(r.ok for r in results)
        # a second client reaches it as a remote scheduler, with the certificates ...
        with open_client(address, security=sec) as other:
            assert other.submit(_square, 7).result() == 49
        # ... and is refused without them, or over plain TCP
        with pytest.raises(InputError, match="needs certificates"):
            with open_client(address, timeout=5):
                pass
        with pytest.raises(InputError, match="not encrypted"):
            with open_client(address.replace("tls://", "tcp://"), security=sec, timeout=5):
                pass


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_batch_cli_on_a_tls_local_cluster(tmp_path, capsys):
    sec = _security_file(tmp_path)
    out = tmp_path / "out"
    status = main(["batch", "fit", str(data_path("free-ssi.modes.csv")), "--out", str(out), "--security", str(sec),
                   "--workers", "1", "--quiet", "--", "--tyre", str(data_path("table9.tyre.toml"))])
    err = capsys.readouterr().err
    assert status == 0, err
    assert "on TLS" in err
    assert any(out.iterdir())


@pytest.mark.parametrize("text, must", [
    ('ca_file = "ca.pem"\ncert = "cert.pem"\n', "missing key 'key'"),
    ('ca_file = "nope.pem"\ncert = "cert.pem"\nkey = "key.pem"\n', "ca_file = 'nope.pem': no such file"),
    ('ca_file = "ca.pem"\ncert = "cert.pem"\nkey = "key.pem"\npassword = "x"\n', "unknown key 'password'"),
    ('ca_file = "ca.pem"\ncert = "cert.pem"\nkey = "key.pem"\nmin_version = 1.1\n', "min_version = 1.1"),
    ("ca_file = [", "not a readable TOML"),
])
def test_bad_security_file(tmp_path, capsys, text, must):
    _security_file(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "out"
    status = main(["batch", "fit", str(data_path("free-ssi.modes.csv")), "--out", str(out), "--security", str(bad),
                   "--", "--tyre", str(data_path("table9.tyre.toml"))])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and must in err[0] and "bad.toml" in err[0], err
    assert not out.exists()


def test_tls_scheduler_without_certificates_is_one_line(tmp_path, capsys, monkeypatch):
    import dask

    monkeypatch.setitem(dask.config.config.setdefault("distributed", {}).setdefault("comm", {}), "tls", {})
    status = main(["batch", "fit", str(data_path("free-ssi.modes.csv")), "--out", str(tmp_path / "o"),
                   "--scheduler", "tls://127.0.0.1:1", "--", "--tyre", str(data_path("table9.tyre.toml"))])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "needs certificates" in err[0] and "--security" in err[0], err
