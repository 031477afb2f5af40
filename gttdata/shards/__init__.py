"""HDF5 shards of CaptureSamples: layout (schema), writer and reader; DatasetReader lives in ``gttdata.dataset``."""

from __future__ import annotations

from gttdata.shards.reader import ShardReader
from gttdata.shards.schema import SCHEMA_VERSION
from gttdata.shards.writer import ShardInfo, ShardWriter

__all__ = ["SCHEMA_VERSION", "ShardInfo", "ShardReader", "ShardWriter"]
