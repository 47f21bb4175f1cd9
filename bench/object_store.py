"""Object-store clients for campaign bags, measured side by side against a local S3-protocol server (moto).

    pip install obstore  # the contestant; s3fs and moto come with the campaign and test extras
    python bench/object_store.py [--bags 12] [--mb 8]

Uploads N bags of M MB, then, alternating the clients each repetition, lists them and downloads each to a
file: fsspec + s3fs (what bagfault uses: globbing and folder listing included) against obstore (a Rust client
with prefix listing only). Prints the median seconds of each.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--bags', type=int, default=12)
    parser.add_argument('--mb', type=int, default=8)
    parser.add_argument('--repeat', type=int, default=5)
    args = parser.parse_args()
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    server = subprocess.Popen([sys.executable, '-m', 'moto.server', '-H', '127.0.0.1', '-p', str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(2)
        os.environ.update(AWS_ENDPOINT_URL=f'http://127.0.0.1:{port}', AWS_ACCESS_KEY_ID='k',
                          AWS_SECRET_ACCESS_KEY='s', AWS_DEFAULT_REGION='us-east-1')
        import boto3
        import fsspec
        import obstore
        from obstore.store import S3Store

        client = boto3.client('s3')
        client.create_bucket(Bucket='bench-bags')
        payload = os.urandom(args.mb << 20)
        for n in range(args.bags):
            client.put_object(Bucket='bench-bags', Key=f'fleet/bag{n:03d}.mcap', Body=payload)

        def with_s3fs(folder: Path) -> None:
            fs = fsspec.filesystem('s3', skip_instance_cache=True)
            for key in sorted(fs.glob('bench-bags/fleet/*.mcap')):
                fs.get_file(key, str(folder / Path(key).name))

        def with_obstore(folder: Path) -> None:
            store = S3Store('bench-bags', endpoint=f'http://127.0.0.1:{port}', region='us-east-1',
                            client_options={'allow_http': True})
            keys = sorted(m['path'] for batch in obstore.list(store, prefix='fleet/') for m in batch
                          if m['path'].endswith('.mcap'))
            for key in keys:
                (folder / Path(key).name).write_bytes(bytes(obstore.get(store, key).bytes()))

        times: dict[str, list[float]] = {'s3fs': [], 'obstore': []}
        for _ in range(args.repeat):
            for name, fetch in (('s3fs', with_s3fs), ('obstore', with_obstore)):
                with tempfile.TemporaryDirectory() as folder:
                    began = time.perf_counter()
                    fetch(Path(folder))
                    times[name].append(time.perf_counter() - began)
        print(json.dumps({name: round(statistics.median(t), 3) for name, t in times.items()} |
                         {'bags': args.bags, 'mb': args.mb}))
    finally:
        server.terminate()


if __name__ == '__main__':
    main()
