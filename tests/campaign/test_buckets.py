"""Campaigns over bags in a bucket, against a real S3-protocol HTTP server started here (moto's standalone
server, in a process of its own on 127.0.0.1, with IAM authentication on): listing by glob, a rosbag2 folder
in the bucket, the node cache (one download per bag, reused by the next campaign), a missing bucket, refused
credentials and a bag deleted mid-campaign. The expected tables are those of the same campaign over the same
bags on local disk.
"""

from __future__ import annotations

import contextlib
import shutil
import time
from pathlib import Path
from typing import Any

import pytest
from support.corpus import InterruptAfter, campaign_file
from support.helpers import FIXTURES

from bagfault.cli import main

pq = pytest.importorskip('pyarrow.parquet', reason='campaign extra not installed')
boto3 = pytest.importorskip('boto3', reason='moto[server] (test extra) not installed')
pytest.importorskip('s3fs', reason='campaign extra not installed')
from support.s3 import BUCKET, S3Server  # noqa: E402 - after the skips: it needs boto3

BIAS = 'faults.bias.config.angular_velocity_z_bias'


@pytest.fixture(scope='module')
def server(tmp_path_factory: pytest.TempPathFactory) -> Any:
    s3 = S3Server(tmp_path_factory.mktemp('moto'))
    s3.s3.create_bucket(Bucket=BUCKET)
    yield s3
    s3.stop()


@pytest.fixture
def store(server: S3Server, corpus: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> S3Server:
    """The corpus's bags and a rosbag2 folder uploaded under a fresh prefix; the AWS variables set; a private
    cache."""
    prefix = tmp_path.name
    for name in ('a.mcap', 'b.mcap'):
        server.s3.upload_file(str(corpus / 'bags' / name), BUCKET, f'{prefix}/bags/{name}')
    for env, value in server.env.items():
        monkeypatch.setenv(env, value)
    monkeypatch.setenv('BAGFAULT_CACHE', str(tmp_path / 'cache'))
    server.prefix = prefix  # type: ignore[attr-defined]
    return server


def rows(directory: Path) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.items() if k not in ('seconds', 'cpu_s', 'bag', 'key', 'output')}  # keys: BLAKE3 vs ETag
            for row in pq.read_table(directory / 'results.parquet').to_pylist()]


CAMPAIGN = f"""
    campaign: bucket
    scenario: drift.yaml
    bags: [%s]
    sweep:
      {BIAS}: [0.05, 0.2]
    seeds: [0, 1]
"""


def test_a_campaign_over_a_bucket_matches_the_same_bags_on_disk_and_downloads_each_once(
        store: S3Server, corpus: Path, tmp_path: Path) -> None:
    prefix = store.prefix  # type: ignore[attr-defined]
    local = campaign_file(corpus, CAMPAIGN % 'bags/*.mcap')
    assert main(['campaign', str(local), '-o', str(tmp_path / 'local'), '--workers', '2']) in (0, 1)
    remote = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/{prefix}/bags/*.mcap')
    code = main(['campaign', str(remote), '-o', str(tmp_path / 'remote'), '--workers', '2'])
    assert code in (0, 1) and rows(tmp_path / 'remote') == rows(tmp_path / 'local')
    table = pq.read_table(tmp_path / 'remote' / 'results.parquet').to_pylist()
    assert {r['bag'] for r in table} == {f's3://{BUCKET}/{prefix}/bags/a.mcap', f's3://{BUCKET}/{prefix}/bags/b.mcap'}
    # 4 jobs per bag on 2 workers: each bag downloaded once, by whichever job came first
    assert store.gets(f'{prefix}/bags/a.mcap') == 1 and store.gets(f'{prefix}/bags/b.mcap') == 1
    cached = sorted((tmp_path / 'cache').rglob('*.mcap'))
    assert [p.name for p in cached] == ['a.mcap', 'b.mcap']
    inodes = [p.stat().st_ino for p in cached]
    assert main(['campaign', str(remote), '-o', str(tmp_path / 'again'), '--workers', '2']) == code
    assert store.gets(f'{prefix}/bags/a.mcap') == 1 and store.gets(f'{prefix}/bags/b.mcap') == 1  # the cache's
    assert [p.stat().st_ino for p in sorted((tmp_path / 'cache').rglob('*.mcap'))] == inodes
    assert rows(tmp_path / 'again') == rows(tmp_path / 'local')


def test_a_rosbag2_folder_in_a_bucket(store: S3Server, corpus: Path, tmp_path: Path) -> None:
    prefix = store.prefix  # type: ignore[attr-defined]
    folder = FIXTURES / 'rover_3s_sqlite3'
    for file in folder.iterdir():
        store.s3.upload_file(str(file), BUCKET, f'{prefix}/rosbag2/rover/{file.name}')
    (corpus / 'rover.yaml').write_text('injectors: []\nfaults: []\nassertions:\n'
                                       '  - {id: imu, type: message_count, topic: /sensors/imu_raw, min: 300}\n')
    path = campaign_file(corpus, f"""
        campaign: folders
        scenario: rover.yaml
        bags: [s3://{BUCKET}/{prefix}/rosbag2/*]
    """)
    assert main(['campaign', str(path), '-o', str(tmp_path / 'out'), '--workers', '1']) == 0
    table = pq.read_table(tmp_path / 'out' / 'results.parquet').to_pylist()
    assert [(r['bag'], r['status']) for r in table] == [(f's3://{BUCKET}/{prefix}/rosbag2/rover', 'passed')]
    local = tmp_path / 'local'
    shutil.copytree(folder, local)
    assert main(['run', str(corpus / 'rover.yaml'), str(local), '-o', str(tmp_path / 'check.mcap')]) == 0


def test_a_missing_bucket_refused_or_missing_credentials_are_one_line(store: S3Server, corpus: Path, tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    path = campaign_file(corpus, CAMPAIGN % 's3://no-such-bucket-here/bags/*.mcap')
    assert main(['campaign', str(path), '-o', str(tmp_path / 'out')]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and "bucket 'no-such-bucket-here' does not exist" in error
    assert not (tmp_path / 'out').exists()
    monkeypatch.setenv('AWS_SECRET_ACCESS_KEY', 'not-the-secret')
    path = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/{store.prefix}/bags/*.mcap')  # type: ignore[attr-defined]
    assert main(['campaign', str(path), '-o', str(tmp_path / 'out')]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'access refused by the store' in error and 'AWS_' in error
    assert not (tmp_path / 'out').exists()
    for name in ('AWS_ACCESS_KEY_ID', 'AWS_SECRET_ACCESS_KEY', 'AWS_PROFILE', 'AWS_SESSION_TOKEN'):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv('AWS_SHARED_CREDENTIALS_FILE', str(tmp_path / 'none'))
    monkeypatch.setenv('AWS_CONFIG_FILE', str(tmp_path / 'none'))
    monkeypatch.setenv('AWS_EC2_METADATA_DISABLED', 'true')  # no instance role to ask on this machine
    assert main(['campaign', str(path), '-o', str(tmp_path / 'out')]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'no usable credentials' in error and 'AWS_ACCESS_KEY_ID' in error
    assert not (tmp_path / 'out').exists()


class _DeleteAfterFirst:
    """A progress display that deletes an object from the bucket when the first job has finished."""

    def __init__(self, server: S3Server, key: str) -> None:
        from bagfault.progress import JobProgress

        self.bar = JobProgress(enabled=False)
        self.server, self.key = server, key

    def __getattr__(self, name: str) -> Any:
        return getattr(self.bar, name)

    def finished(self, status: str) -> None:
        self.bar.finished(status)
        self.server.s3.delete_object(Bucket=BUCKET, Key=self.key)


def test_a_bag_deleted_mid_campaign_is_an_error_row_and_the_others_complete(store: S3Server, corpus: Path,
                                                                             tmp_path: Path) -> None:
    from bagfault import api

    prefix = store.prefix  # type: ignore[attr-defined]
    path = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/{prefix}/bags/*.mcap')
    result = api.campaign(path, tmp_path / 'out', workers=1,
                          progress=_DeleteAfterFirst(store, f'{prefix}/bags/b.mcap'))  # type: ignore[arg-type]
    table = pq.read_table(tmp_path / 'out' / 'results.parquet').to_pylist()
    statuses = [(r['bag'].rsplit('/', 1)[1], r['status']) for r in table]
    assert [s for b, s in statuses if b == 'a.mcap'] != [] and all(s != 'error' for b, s in statuses if b == 'a.mcap')
    gone = [r for r in table if r['bag'].endswith('b.mcap')]
    assert len(gone) == 4 and all(r['status'] == 'error' and 'no such object' in r['message'] for r in gone)
    assert result.failed


def test_results_written_to_a_bucket_survive_a_stop_and_resume_from_it(store: S3Server, corpus: Path,
                                                                       tmp_path: Path) -> None:
    """-o s3://...: the tables and report land in the bucket; a campaign stopped after 3 jobs has uploaded those
    3, and --resume runs only the other 5, from the bucket, to the table of an uninterrupted run."""
    from bagfault import api
    from bagfault.errors import OutputError

    prefix = store.prefix  # type: ignore[attr-defined]
    path = campaign_file(corpus, CAMPAIGN % 'bags/*.mcap')
    target = f's3://{BUCKET}/{prefix}/results/run1'
    with pytest.raises(KeyboardInterrupt):
        api.campaign(path, target, workers=1, progress=InterruptAfter(3))  # type: ignore[arg-type]
    listed = store.s3.list_objects_v2(Bucket=BUCKET, Prefix=f'{prefix}/results/run1/jobs/')
    assert len(listed.get('Contents', [])) == 3
    result = api.campaign(path, target, workers=1, resume=True)
    assert result.ran == 5
    names = {o['Key'].rsplit('/run1/', 1)[1] for o in
             store.s3.list_objects_v2(Bucket=BUCKET, Prefix=f'{prefix}/results/run1/')['Contents']}
    assert {'results.parquet', 'results.csv', 'campaign.json', 'report.html'} <= names
    store.s3.download_file(BUCKET, f'{prefix}/results/run1/results.parquet', str(tmp_path / 'resumed.parquet'))
    assert main(['campaign', str(path), '-o', str(tmp_path / 'whole'), '--workers', '1']) in (0, 1)
    resumed = [{k: v for k, v in r.items() if k not in ('seconds', 'cpu_s')} for r in pq.read_table(tmp_path / 'resumed.parquet')
               .to_pylist()]
    assert resumed == [{k: v for k, v in r.items() if k not in ('seconds', 'cpu_s')} for r in pq.read_table(
        tmp_path / 'whole' / 'results.parquet').to_pylist()]
    with pytest.raises(OutputError, match=f'{target}: holds 8 results of a campaign already'):
        api.campaign(path, target, workers=1)  # without --resume, as for a local folder
    with pytest.raises(OutputError, match="bucket 'no-results-bucket' does not exist"):
        api.campaign(path, 's3://no-results-bucket/run1', workers=1)  # said before any job, not at the upload


def test_a_table_in_the_bucket_that_bagfault_did_not_write_is_not_replaced(store: S3Server, corpus: Path) -> None:
    """-o s3://...: the prefix's results.csv of someone else's stops the campaign before any job, as a local
    folder's does (it was replaced without --force); --force replaces it; a resumed campaign replaces the
    bucket's tables it wrote itself (their marks came along)."""
    from bagfault import api
    from bagfault.errors import OutputError

    prefix = store.prefix  # type: ignore[attr-defined]
    path = campaign_file(corpus, CAMPAIGN % 'bags/a.mcap')
    target = f's3://{BUCKET}/{prefix}/theirs'
    store.s3.put_object(Bucket=BUCKET, Key=f'{prefix}/theirs/results.csv', Body=b'name,score\nmine,1\n')
    said = rf'{target}/results\.csv: a campaign file exists and bagfault did not write it'
    with pytest.raises(OutputError, match=said):
        api.campaign(path, target, workers=1)
    body = store.s3.get_object(Bucket=BUCKET, Key=f'{prefix}/theirs/results.csv')['Body'].read()
    assert body == b'name,score\nmine,1\n'
    assert 'Contents' not in store.s3.list_objects_v2(Bucket=BUCKET, Prefix=f'{prefix}/theirs/jobs/')
    api.campaign(path, target, workers=1, force=True)
    body = store.s3.get_object(Bucket=BUCKET, Key=f'{prefix}/theirs/results.csv')['Body'].read()
    assert body.startswith(b'job,')
    assert api.campaign(path, target, workers=1, resume=True).ran == 0  # its own tables: replaced, no --force


def test_the_cache_is_bounded_and_never_evicts_a_bag_in_use(store: S3Server, monkeypatch: pytest.MonkeyPatch) -> None:
    """Room for one bag: fetching b removes a (the entry unused longest); fetching a again while b is in use
    keeps b (over the limit rather than pulling a bag from under a job); a second holder shares a download."""
    import blake3

    from bagfault.io.objects import fetched, list_bags

    a, b = list_bags(f's3://{BUCKET}/{store.prefix}/bags/*.mcap')  # type: ignore[attr-defined]
    monkeypatch.setenv('BAGFAULT_CACHE_GB', str(a.files[0].size * 1.5 / 1e9))
    with fetched(a) as first, fetched(a) as second:
        assert first.downloaded and not second.downloaded and second.path == first.path
        # the node hashes the bag once, beside it in the cache; every later job is handed the digest
        assert list(second.digests.values()) == [blake3.blake3(first.path.read_bytes()).hexdigest()]
        assert (first.path.parent / '.digests.json').exists()
    with fetched(b) as other:
        assert other.downloaded
    assert not first.path.exists() and other.path.exists()
    with fetched(b) as held:
        with fetched(a) as again:
            assert again.downloaded and held.path.exists()  # b is in use: kept, though over the limit
        assert held.path.exists()


@pytest.mark.parametrize('change', ['a byte flipped', 'cut short', 'replaced by a symlink', 'record lost'])
def test_a_cached_bag_that_changed_is_fetched_again(store: S3Server, change: str) -> None:
    """A cached copy is reused only while it is the download: each file of its listed size and of the BLAKE3
    recorded when it was downloaded (a copy edited in place, cut short or swapped was used as it was)."""
    import os

    import blake3

    from bagfault.io.objects import fetched, list_bags

    a = list_bags(f's3://{BUCKET}/{store.prefix}/bags/a.mcap')[0]  # type: ignore[attr-defined]
    key = f'{store.prefix}/bags/a.mcap'  # type: ignore[attr-defined]
    original = store.s3.get_object(Bucket=BUCKET, Key=key)['Body'].read()
    gets = store.gets(key)
    from bagfault.io import sources

    hashed: list[Path] = []
    real = sources._blake3

    def counted(file: Path, *args: object) -> str:
        hashed.append(file)
        return real(file, *args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sources, '_blake3', counted)
        with fetched(a) as first:
            assert first.downloaded
        with fetched(a) as reused:
            assert not reused.downloaded  # unchanged: the cache's
    assert hashed == [first.path]  # a download is hashed once, its reuse not at all
    path = first.path
    if change == 'a byte flipped':
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0xFF
        path.write_bytes(bytes(data))
        os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns))
    elif change == 'cut short':
        with path.open('r+b') as stream:
            stream.truncate(len(original) - 100)
    elif change == 'replaced by a symlink':
        other = path.with_name('elsewhere.mcap')
        other.write_bytes(original)
        path.unlink()
        path.symlink_to(other)
    else:
        (path.parent / '.content.json').unlink()
    with fetched(a) as again:
        assert again.downloaded and store.gets(key) == gets + 2
        assert not again.path.is_symlink() and again.path.read_bytes() == original
        assert list(again.digests.values()) == [blake3.blake3(original).hexdigest()]


def test_a_job_waits_for_a_download_never_for_another_jobs_run(store: S3Server) -> None:
    """Two jobs of one bag on one node: the second gets the bag while the first still holds it in use, from the
    first's download. (Before, two jobs that both found the bag missing could leave the second waiting for the
    first's whole run: the download lock was the use lock; it has one of its own now.)"""
    import threading

    from bagfault.io.objects import fetched, list_bags

    bag = list_bags(f's3://{BUCKET}/{store.prefix}/bags/a.mcap')[0]  # type: ignore[attr-defined]
    inside, second_done = threading.Event(), threading.Event()
    found: list[object] = []

    def first_job() -> None:
        with fetched(bag) as held:
            found.append(held.downloaded)
            inside.set()
            second_done.wait(timeout=20)  # "running" until the second job has its bag

    def second_job() -> None:
        inside.wait(timeout=20)
        with fetched(bag) as held:
            found.append(held.downloaded)
        second_done.set()

    threads = [threading.Thread(target=first_job), threading.Thread(target=second_job)]
    for thread in threads:
        thread.start()
    assert second_done.wait(timeout=15), 'the second job waited for the first job to end'
    for thread in threads:
        thread.join(timeout=20)
    assert found == [True, False]  # one download, shared


class _Silent:
    """A TCP server on 127.0.0.1 that accepts every connection and never answers (a stuck proxy or endpoint)."""

    def __init__(self) -> None:
        import socket
        import threading

        self.socket = socket.create_server(('127.0.0.1', 0))
        self.url = f'http://127.0.0.1:{self.socket.getsockname()[1]}'
        self.held: list[Any] = []
        self.thread = threading.Thread(target=self._accept, daemon=True)
        self.thread.start()

    def _accept(self) -> None:
        with contextlib.suppress(OSError):
            while True:
                self.held.append(self.socket.accept()[0])

    def close(self) -> None:
        self.socket.close()
        for connection in self.held:
            connection.close()


def test_a_store_that_never_answers_is_one_line_within_a_bounded_time(corpus: Path, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """An endpoint that accepts connections and never answers: botocore waits 60 s per read and retries, s3fs
    retries that five times (the campaign waited past 60 s without a word). Every call has a timeout and a
    retry budget, and the line says it was spent."""
    from bagfault.io import objects

    monkeypatch.setattr(objects, 'STORE_TIMEOUT', 2.0)  # the bound itself (10 s) would make this a minute
    silent = _Silent()
    try:
        monkeypatch.setenv('AWS_ENDPOINT_URL', silent.url)
        for name, value in (('AWS_ACCESS_KEY_ID', 'k'), ('AWS_SECRET_ACCESS_KEY', 's'),
                            ('AWS_DEFAULT_REGION', 'us-east-1')):
            monkeypatch.setenv(name, value)
        monkeypatch.setenv('BAGFAULT_CACHE', str(tmp_path / 'cache'))
        path = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/bags/*.mcap')
        began = time.monotonic()
        assert main(['campaign', str(path), '-o', str(tmp_path / 'out')]) == 2
        seconds = time.monotonic() - began
    finally:
        silent.close()
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'no answer from the store within 2 s, 3 tries' in error, error
    assert seconds < 30, seconds  # the listing asks twice: 2 x 3 tries x 2 s, and the start
    assert not (tmp_path / 'out').exists()
