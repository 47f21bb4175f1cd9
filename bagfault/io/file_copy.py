"""Bytes of one file copied into another at given offsets, in the kernel where it can (copy_file_range)."""

from __future__ import annotations

import errno
import os

NOT_IN_KERNEL = (errno.EXDEV, errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.EBADF)
IN_KERNEL = hasattr(os, 'copy_file_range')


def copy_range(source: int, target: int, offset: int, length: int, at: int, *, in_kernel: bool = IN_KERNEL) -> bool:
    """`length` bytes of `source` from `offset` into `target` at `at` (no file position moves); False when the
    kernel could not copy them (another file system, an old kernel) and they went through user space, so the
    caller need not try the kernel again."""
    done = 0
    if in_kernel:
        try:
            while done < length:
                copied = os.copy_file_range(source, target, length - done, offset + done, at + done)
                if copied == 0:
                    break
                done += copied
        except OSError as exc:
            if exc.errno not in NOT_IN_KERNEL:
                raise  # a full disk, a lost mount: the write failed
            in_kernel = False
    while done < length:
        data = os.pread(source, min(length - done, 1 << 22), offset + done)
        if not data:
            raise OSError(f'the input ended {length - done} bytes before offset {offset + length}')
        done += os.pwrite(target, data, at + done)
    return in_kernel
