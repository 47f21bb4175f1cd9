"""A real S3-protocol HTTP server for tests: moto's standalone server in a process of its own on 127.0.0.1,
with IAM authentication on (refused credentials are refused), and a user whose keys the tests use."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import boto3

BUCKET = 'fleet-logs'


class S3Server:
    """moto_server on a free loopback port; the first actions create a user whose keys the tests use."""

    def __init__(self, folder: Path) -> None:
        with socket.socket() as probe:
            probe.bind(('127.0.0.1', 0))
            self.port = probe.getsockname()[1]
        self.log = folder / 'moto.log'
        env = {**os.environ, 'INITIAL_NO_AUTH_ACTION_COUNT': '3'}  # then every request is authenticated
        self.process = subprocess.Popen([sys.executable, '-m', 'moto.server', '-H', '127.0.0.1', '-p', str(self.port)],
                                        stdout=self.log.open('wb'), stderr=subprocess.STDOUT, env=env)
        self.url = f'http://127.0.0.1:{self.port}'
        deadline = time.monotonic() + 30
        while True:
            try:
                socket.create_connection(('127.0.0.1', self.port), timeout=0.5).close()
                break
            except OSError:
                assert time.monotonic() < deadline and self.process.poll() is None, self.log.read_text()
                time.sleep(0.1)
        kw = {'endpoint_url': self.url, 'region_name': 'us-east-1', 'aws_access_key_id': 'bootstrap',
              'aws_secret_access_key': 'bootstrap'}
        iam = boto3.client('iam', **kw)
        iam.create_user(UserName='ci')
        key = iam.create_access_key(UserName='ci')['AccessKey']
        iam.put_user_policy(UserName='ci', PolicyName='all', PolicyDocument=json.dumps(
            {'Version': '2012-10-17', 'Statement': [{'Effect': 'Allow', 'Action': '*', 'Resource': '*'}]}))
        self.env = {'AWS_ENDPOINT_URL': self.url, 'AWS_ACCESS_KEY_ID': key['AccessKeyId'],
                    'AWS_SECRET_ACCESS_KEY': key['SecretAccessKey'], 'AWS_DEFAULT_REGION': 'us-east-1'}
        self.s3 = boto3.client('s3', endpoint_url=self.url, region_name='us-east-1',
                               aws_access_key_id=key['AccessKeyId'], aws_secret_access_key=key['SecretAccessKey'])

    def gets(self, key: str) -> int:
        """GET requests for one object so far (the server's access log)."""
        return len(re.findall(rf'"GET /{BUCKET}/{re.escape(key)} HTTP', self.log.read_text(errors='replace')))

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=10)
