"""`python -m anisognn train ARGS...` for torchrun, which then prints how many references other
than its own hold the process group that the command made; 0 when the command freed it.

Used by tests/test_gnn_training.py: a group that outlives the command is still alive at
interpreter exit, where gloo's worker threads abort the process now and then."""
import os
import sys

import torch.distributed as dist

from anisognn import cli

made = []
init = dist.init_process_group


def recording_init(*args, **kwargs):
    init(*args, **kwargs)
    made.append(dist.group.WORLD)


dist.init_process_group = recording_init
cli.main(sys.argv[1:])
group = made.pop()
# sys.getrefcount counts its own argument and the name `group`
print(f"rank {os.environ['RANK']}: other references to the group: {sys.getrefcount(group) - 2}",
      flush=True)
# dropping the last reference frees the group (and joins gloo's worker threads) now, not at
# interpreter exit, where this script's own reference would make it abort now and then
del group
