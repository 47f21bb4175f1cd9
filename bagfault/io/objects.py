"""Bags in object storage (`s3://`, `gs://`, `az://`): listed by glob, downloaded once per machine into a
content-addressed cache, which the readers need (they seek, and chunk copy needs a file descriptor).

Access goes through fsspec (s3fs for S3), measured against obstore's Rust client (bench/object_store.py,
2026-11-26: listing and fetching 12 bags of 8 MB from a local S3 server, 0.27 s with s3fs, 0.32 s with
obstore): as fast here, and fsspec globs and lists folders where obstore lists prefixes only, with one API
for gs:// (gcsfs) and az:// (adlfs) too; credentials come from each
store's standard chain (for S3 the AWS variables, profiles and instance roles, `AWS_ENDPOINT_URL` for
another S3-protocol server), never from the campaign file. A bag is a single object (`.mcap`, `.bag`,
`.db3`) or a rosbag2 folder (a prefix holding `metadata.yaml`).

The cache (`BAGFAULT_CACHE`, default `~/.cache/bagfault/objects`) keys a bag by the ETags and sizes of its
objects, so a bag is downloaded once and reused by every job and campaign on the machine; a lock file makes
two jobs that want the same bag download it once; entries not used longest are removed when the cache grows
past `BAGFAULT_CACHE_GB` (default 50), never one in use.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

from bagfault import settings
from bagfault.errors import InputError, OutputError
from bagfault.io.marks import sidecar
from bagfault.io.regular import read_text
from bagfault.io.sources import StatKey, digests_of, input_files, stat_key
from bagfault.log import log

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

SCHEMES = {'s3': 's3fs', 'gs': 'gcsfs', 'gcs': 'gcsfs', 'az': 'adlfs', 'abfs': 'adlfs'}
BAG_SUFFIXES = ('.mcap', '.bag', '.db3', '.mcap.zstd', '.db3.zstd')


def is_remote(text: str) -> bool:
    """Whether a `bags:` entry is an object-store URL."""
    scheme, sep, _ = text.partition('://')
    return bool(sep) and scheme in SCHEMES


@dataclass(frozen=True)
class RemoteFile:
    """One object of a bag: its name within the bag, its size and version tag."""

    name: str
    url: str
    size: int
    etag: str


@dataclass(frozen=True)
class RemoteBag:
    """A bag in a bucket: one object, or the objects of a rosbag2 folder."""

    url: str
    files: tuple[RemoteFile, ...]
    folder: bool

    def __str__(self) -> str:
        return self.url

    @property
    def name(self) -> str:
        """The bag's file or folder name."""
        return PurePosixPath(self.url.split('://', 1)[1]).name

    @property
    def digest(self) -> str:
        """What identifies the content: the objects' names, sizes and ETags."""
        text = json.dumps([[f.name, f.size, f.etag] for f in self.files], sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON for a job spec."""
        return {'url': self.url, 'folder': self.folder, 'files': [asdict(f) for f in self.files]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RemoteBag:
        """The inverse of to_dict."""
        return cls(data['url'], tuple(RemoteFile(**f) for f in data['files']), bool(data['folder']))


STORE_TIMEOUT = 10.0  # seconds to connect, and between two reads of an answer (S3 answers in well under 1)
STORE_TRIES = 3  # each request, in all; then the call fails and says so


def filesystem(url: str) -> Any:
    """The fsspec filesystem of a URL's scheme; InputError naming the package when it is not installed.

    S3's client would wait 60 s per read and retry that for minutes on an endpoint that never answers: every
    request here has STORE_TIMEOUT and STORE_TRIES (s3fs retries, botocore does not retry on top of it).
    """
    scheme = url.split('://', 1)[0]
    options: dict[str, Any] = {}
    if scheme in ('s3', 's3a'):
        options = {'config_kwargs': {'connect_timeout': STORE_TIMEOUT, 'read_timeout': STORE_TIMEOUT,
                                     'retries': {'max_attempts': 1, 'mode': 'standard'}}}
    try:
        import fsspec  # type: ignore[import-untyped]  # noqa: PLC0415

        fs = fsspec.filesystem(scheme, skip_instance_cache=True, **options)  # credentials as the environment says
        if options:
            fs.retries = STORE_TRIES
        return fs
    except ImportError:
        raise InputError(f'{url}: reading {scheme}:// needs the {SCHEMES[scheme]} package '
                         f"(pip install 'bagfault[campaign]' installs s3fs)") from None
    except ValueError as exc:
        raise InputError(f'{url}: {exc}') from None


def _etag(info: dict[str, Any]) -> str:
    for key in ('ETag', 'etag', 'md5Hash', 'crc32c', 'LastModified', 'mtime'):
        if info.get(key):
            return str(info[key]).strip('"')
    return ''


def list_bags(pattern: str) -> list[RemoteBag]:
    """The bags a URL glob finds, sorted; InputError for a missing bucket, refused credentials or no match."""
    scheme = pattern.split('://', 1)[0]
    fs = filesystem(pattern)
    path = pattern.split('://', 1)[1]
    bucket = path.split('/', 1)[0]
    try:
        found = fs.glob(path, detail=True)
        if not found and not fs.exists(bucket):
            raise InputError(f'{pattern}: bucket {bucket!r} does not exist (or these credentials cannot see it)')
        bags = []
        for key, info in sorted(found.items()):
            if info.get('type') == 'directory':
                listing = fs.ls(key, detail=True)
                names = {PurePosixPath(i['name']).name: i for i in listing if i.get('type') == 'file'}
                if 'metadata.yaml' in names:
                    files = tuple(RemoteFile(n, f'{scheme}://{i["name"]}', int(i.get('size') or 0), _etag(i))
                                  for n, i in sorted(names.items()))
                    bags.append(RemoteBag(f'{scheme}://{key}', files, folder=True))
            elif key.endswith(BAG_SUFFIXES):
                name = PurePosixPath(key).name
                bags.append(RemoteBag(f'{scheme}://{key}', (RemoteFile(name, f'{scheme}://{key}',
                                                                       int(info.get('size') or 0), _etag(info)),),
                                      folder=False))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - each store's client raises its own kinds (botocore's, gcsfs's, ...)
        raise InputError(f'{pattern}: {_store_problem(exc)}') from None
    return bags


def _store_problem(exc: Exception) -> str:
    """What a store's client said, as one line: refused access and missing credentials named as such."""
    text = ' '.join(str(exc).split())[:200] or type(exc).__name__
    if isinstance(exc, TimeoutError) or 'timeout' in type(exc).__name__.lower():
        return (f'no answer from the store within {STORE_TIMEOUT:g} s, {STORE_TRIES} tries ({text}); '
                'is the endpoint (AWS_ENDPOINT_URL) right and reachable?')
    if isinstance(exc, PermissionError):
        return (f'access refused by the store ({text}); credentials come from the standard chain (for S3: '
                'AWS_ACCESS_KEY_ID, AWS_PROFILE, ...)')
    if 'credential' in type(exc).__name__.lower() or 'credential' in text.lower():
        return (f'no usable credentials ({text}); they come from the standard chain (for S3: AWS_ACCESS_KEY_ID '
                'and AWS_SECRET_ACCESS_KEY, AWS_PROFILE, an instance role)')
    return f'cannot reach the store ({text})'


def cache_root() -> Path:
    """This machine's cache (one folder per Ray node when several run on one machine)."""
    root = settings.cache_folder() or settings.user_cache() / 'objects'
    node = settings.cache_node()
    return root / node if node else root


def cache_limit() -> int:
    """Bytes the cache may hold before the entries unused longest are removed."""
    return int(settings.cache_gigabytes() * 1e9)


@dataclass
class Fetched:
    """A bag on local disk, whether this call downloaded it, and its files' digests (hashed once per node)."""

    path: Path
    downloaded: bool
    digests: dict[StatKey, str]


@contextlib.contextmanager
def fetched(bag: RemoteBag) -> Iterator[Fetched]:
    """The bag as a local file or folder for as long as the `with` lasts (no eviction takes it meanwhile)."""
    root = cache_root()
    entry = root / bag.digest[:32]
    root.mkdir(parents=True, exist_ok=True)
    target = entry / bag.name
    with (root / f'{entry.name}.lock').open('a+b') as lock:
        fcntl.flock(lock, fcntl.LOCK_SH)  # in use: eviction passes it over; other jobs may share it
        downloaded = False
        if not _intact(bag, entry, target):
            # one download per bag and machine, under a lock of its own: a job that waits for another's
            # download waits for that, never for the other job's whole run (which holds the use lock)
            with (root / f'{entry.name}.download').open('a+b') as downloading:
                fcntl.flock(downloading, fcntl.LOCK_EX)
                if not _intact(bag, entry, target):
                    if target.exists() or target.is_symlink():
                        log.warning('%s: the cached copy %s differs from what was downloaded; fetched again',
                                    bag.url, target)
                        _discard(entry, target)
                    _download(bag, entry)
                    _record_content(entry, target)
                    downloaded = True
        (entry / '.used').touch()
        try:
            if downloaded:
                evict(root, cache_limit())
            yield Fetched(target, downloaded, _digests(entry, target))
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


CONTENT = '.content.json'  # each file's size and BLAKE3 as downloaded: what a reused copy must still be


def _files(bag: RemoteBag, target: Path) -> dict[str, Path]:
    """The cached copy's files by their object's name."""
    return {f.name: target / f.name for f in bag.files} if bag.folder else {bag.files[0].name: target}


def _record_content(entry: Path, target: Path) -> None:
    known = _digests(entry, target)  # kept beside the bag: the job's own look at the digests reads them back
    content = {f.name: [f.stat().st_size, known[stat_key(f)]] for f in input_files(target)}
    staging = entry / f'.content.{os.getpid()}.json'
    staging.write_text(json.dumps(content, sort_keys=True))
    os.replace(staging, entry / CONTENT)


def _intact(bag: RemoteBag, entry: Path, target: Path) -> bool:
    """Whether the cached copy is the download, unchanged: every object's file there, of its listed size, and
    every file's BLAKE3 the one recorded at download (hashed again only when a file's stat key changed)."""
    if not target.exists() or target.is_symlink():
        return False
    try:
        recorded = json.loads(read_text(entry / CONTENT))
        files = _files(bag, target)
        if any(not path.is_file() or path.is_symlink() or path.stat().st_size != remote.size
               for remote, path in zip(bag.files, files.values(), strict=True)):
            return False
        present = input_files(target)
        if sorted(f.name for f in present) != sorted(recorded):
            return False
        known = _digests(entry, target)
        return all(recorded[f.name] == [f.stat().st_size, known.get(stat_key(f))] for f in present)
    except (OSError, ValueError, TypeError, KeyError, InputError):
        return False


def _discard(entry: Path, target: Path) -> None:
    for name in (CONTENT, '.digests.json'):
        with contextlib.suppress(FileNotFoundError):
            (entry / name).unlink()
    if target.is_dir() and not target.is_symlink():
        shutil.rmtree(target)
    else:
        target.unlink()


def _digests(entry: Path, target: Path) -> dict[StatKey, str]:
    """The bag's files' BLAKE3 digests, computed by the first job on this node and kept beside the bag."""
    record = entry / '.digests.json'
    with contextlib.suppress(OSError, ValueError, TypeError):
        stored = {tuple(k): v for *k, v in json.loads(read_text(record))}
        if all(stat_key(f) in stored for f in input_files(target)):
            return stored
    known = digests_of(target)
    with contextlib.suppress(OSError):
        staging = record.with_name(f'.digests.{os.getpid()}.json')
        staging.write_text(json.dumps([[*key, digest] for key, digest in known.items()]))
        os.replace(staging, record)
    return known


def _download(bag: RemoteBag, entry: Path) -> None:
    fs = filesystem(bag.url)
    entry.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix='.partial-', dir=entry))
    try:
        into = staging / bag.name if bag.folder else staging
        into.mkdir(exist_ok=True)
        for file in bag.files:
            remote = file.url.split('://', 1)[1]
            try:
                info = fs.info(remote)
            except FileNotFoundError:
                raise InputError(f'{file.url}: no such object (deleted after the campaign listed it?)') from None
            if int(info.get('size') or 0) != file.size or _etag(info) != file.etag:
                raise InputError(f'{file.url}: changed after the campaign listed it (size or ETag); run it again')
            fs.get_file(remote, str(into / file.name))
        os.replace(into / bag.name if not bag.folder else into, entry / bag.name)
    except FileNotFoundError:
        raise InputError(f'{bag.url}: no such object (deleted after the campaign listed it?)') from None
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - the store client's own kinds
        raise InputError(f'{bag.url}: cannot download: {_store_problem(exc)}') from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def evict(root: Path, limit: int) -> list[Path]:
    """Remove the entries used longest ago until the cache holds at most `limit` bytes; never one in use."""
    entries = []
    for lock in root.glob('*.lock'):
        entry = root / lock.stem
        if entry.is_dir():
            size = sum(p.stat().st_size for p in entry.rglob('*') if p.is_file())
            used = (entry / '.used').stat().st_mtime if (entry / '.used').exists() else 0.0
            entries.append((used, entry, size, lock))
    total = sum(size for _, _, size, _ in entries)
    removed = []
    for _, entry, size, lock_path in sorted(entries):
        if total <= limit:
            break
        with lock_path.open('a+b') as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # a job has it
            shutil.rmtree(entry, ignore_errors=True)
            total -= size
            removed.append(entry)
    return removed


@dataclass
class Staged:
    """A bucket prefix's local stand-in, and the files under `outputs/` the bucket holds already."""

    path: Path
    outputs: set[str]


@contextlib.contextmanager
def staged_folder(url: str, *, resume: bool, guarded: Sequence[str] = ()) -> Iterator[Staged]:
    """A local folder standing for a bucket prefix (a campaign's `-o s3://...`): the prefix's `jobs/` first when
    resuming, and everything written there uploaded when the `with` ends, also after an error or Ctrl-C, so
    `--resume` can continue from the bucket. Kept (and named) only when the upload fails. The `guarded` files
    the prefix holds already come down with their marks (io/marks.py), so the caller's output checks judge
    them as they judge local files: one bagfault did not write is not replaced without --force."""
    fs = filesystem(url)
    remote = url.split('://', 1)[1].rstrip('/')
    staging = Path(tempfile.mkdtemp(prefix='bagfault-campaign-'))
    keep = False
    try:
        try:
            bucket = remote.split('/', 1)[0]
            if not fs.exists(bucket):  # before any job: the upload at the end would fail after all of them
                raise OutputError(f'{url}: bucket {bucket!r} does not exist (or these credentials cannot see it)')
            stored = fs.glob(f'{remote}/jobs/*.json')
            if stored and not resume:
                raise OutputError(f'{url}: holds {len(stored)} results of a campaign already; --resume continues '
                                  'it (reruns only what is missing or changed), or choose another -o')
            if stored:
                (staging / 'jobs').mkdir()
            for key in stored:
                fs.get_file(key, str(staging / 'jobs' / PurePosixPath(key).name))
            for name in guarded:
                for key in (f'{remote}/{name}', f'{remote}/{sidecar(Path(name)).name}'):
                    if fs.exists(key):
                        fs.get_file(key, str(staging / PurePosixPath(key).name))
            finished = {PurePosixPath(k).stem for k in stored}  # outputs of jobs whose result was stored
            outputs = {PurePosixPath(k).name for k in fs.glob(f'{remote}/outputs/*')
                       if PurePosixPath(k).stem in finished} if resume else set()
        except OutputError:
            raise
        except Exception as exc:  # noqa: BLE001 - the store client's own kinds
            raise InputError(f'{url}: {_store_problem(exc)}') from None
        try:
            yield Staged(staging, outputs)
        finally:
            try:
                for path in sorted(p for p in staging.rglob('*') if p.is_file()):
                    fs.put_file(str(path), f'{remote}/{path.relative_to(staging).as_posix()}')
            except Exception as exc:  # noqa: BLE001 - the store client's own kinds
                keep = True
                raise InputError(f"{url}: cannot upload the campaign's files: {_store_problem(exc)}; they are in "
                                 f'{staging}') from None
    finally:
        if not keep:
            shutil.rmtree(staging, ignore_errors=True)
