"""The HDF5 shard layout (schema version, dataset names, dtypes, filters, attributes) as the single source of truth."""

from __future__ import annotations

from dataclasses import dataclass

from gttdata.errors import ShardFormatError

__all__ = [
    "ATTRS_DIGEST_SINCE_MINOR",
    "COMPRESSIONS",
    "GT_TOLERANCE_M",
    "FieldSpec",
    "ROOT_ATTRS",
    "SAMPLE_ATTRS",
    "SAMPLE_FIELDS",
    "SAMPLES_GROUP",
    "SCHEMA_VERSION",
    "SHARD_SUFFIX",
    "TMP_SUFFIX",
    "VARIANT_ATTRS",
    "VARIANT_FIELDS",
    "VARIANTS_GROUP",
    "check_schema_version",
    "dataset_kwargs",
    "sample_group_name",
    "shard_file_name",
]

#: Shard layout version ``MAJOR.MINOR``. Readers accept any minor of their major and refuse other majors.
#: 1.1 (from 1.0): root attribute ``skeletons``; a skeleton may carry ``extra_bones`` and parents that
#: follow their children. 1.0 shards read unchanged.
#: 1.2 (from 1.1): root attribute ``attrs_sha256``, a SHA-256 over every attribute of the file
#: (:func:`gttdata.shards.digest.attrs_digest`); 1.0 and 1.1 shards read with a logged warning that
#: their attribute text is unchecked.
SCHEMA_VERSION = "1.2"

#: First minor version (of major 1) whose shards must carry the attribute checksum.
ATTRS_DIGEST_SINCE_MINOR = 2

#: Group holding one subgroup per sample, named by :func:`sample_group_name`.
SAMPLES_GROUP = "samples"
#: Subgroup of a sample holding its capture-level variants, one subgroup per variant name.
VARIANTS_GROUP = "variants"
SHARD_SUFFIX = ".h5"
TMP_SUFFIX = ".tmp"

#: Largest rounding error allowed when a ground-truth array in metres is stored as float32.
GT_TOLERANCE_M = 1e-6

#: Names accepted as ``compression`` (the recipe's ``shard.compression``); see :func:`dataset_kwargs`.
COMPRESSIONS: tuple[str, ...] = ("none", "gzip", "lzf")

# Chosen by measurement (docs/FORMAT.md, "Compression"): byte-shuffle + gzip level 4 gives nearly the
# size of level 9 at a fraction of its write time; lzf is larger but decodes fastest.
_GZIP_LEVEL = 4


@dataclass(frozen=True)
class FieldSpec:
    """One per-sample HDF5 dataset.

    Args:
        name: Dataset name (equal to the :class:`~gttdata.capture.sample.CaptureSample` field).
        dtype: Stored dtype.
        shape: Shape in shape letters (N images, J joints, V cameras).
        units: Units and frame.
        compress: Whether the shard's compression filter applies (False for noisy floats, where the
            measured gain did not pay for the decode time; see docs/FORMAT.md, "Compression").
        lossy: Stored at lower precision than the in-memory float64 when the rounding error stays
            below :data:`GT_TOLERANCE_M` for the whole array, else stored as float64 (reader casts back).
    """

    name: str
    dtype: str
    shape: str
    units: str
    compress: bool = True
    lossy: bool = False


#: Datasets of every sample group (the original capture), in write order.
SAMPLE_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("cam_id", "int32", "N", "camera index in [0, V)"),
    FieldSpec("timestamp_s", "float64", "N", "seconds, capture clock"),
    FieldSpec("stream_index", "int32", "N", "index within the camera stream"),
    FieldSpec("global_order", "int32", "N", "rank in true time"),
    FieldSpec("keypoints_px", "float32", "N J 2", "pixels, NaN where missing", compress=False),
    FieldSpec("visible", "bool", "N J", "observed-joint mask"),
    FieldSpec("keypoints_gt_px", "float32", "N J 2", "pixels, noise-free projection", compress=False),
    FieldSpec("K", "float64", "N 3 3", "pixels, intrinsics per image"),
    FieldSpec("cam_from_world", "float64", "N 4 4", "world->camera rigid transform per image, metres"),
    FieldSpec("image_size", "int32", "V 2", "(width, height) pixels per camera"),
    FieldSpec(
        "points3d", "float32", "N J 3", "metres, world frame (ground truth)", compress=False, lossy=True
    ),
    FieldSpec("affinity_nbr", "int32", "N 2", "previous/next other-camera image, -1 where none"),
    FieldSpec("affinity_w", "float64", "N 2", "interpolation weights of affinity_nbr", compress=False),
)

#: Datasets of each ``variants/<name>`` group; the variant shares the original's ground truth:
#: ``points3d_variant = variant_from_orig . points3d`` and every other field is the original's.
VARIANT_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("keypoints_px", "float32", "N J 2", "pixels, NaN where missing", compress=False),
    FieldSpec("visible", "bool", "N J", "observed-joint mask"),
    FieldSpec("K", "float64", "N 3 3", "pixels, intrinsics per image"),
    FieldSpec("cam_from_world", "float64", "N 4 4", "world->camera rigid transform per image, metres"),
    FieldSpec("keypoints_gt_px", "float32", "N J 2", "pixels, noise-free projection", compress=False),
    FieldSpec("variant_from_orig", "float64", "4 4", "rigid transform, metres"),
)

#: Root attributes of every shard file.
ROOT_ATTRS: dict[str, str] = {
    "schema_version": f"shard layout version, '{SCHEMA_VERSION}'",
    "generator": "'gttdata <version>' that wrote the file",
    "recipe_hash": "SHA-256 of the canonical recipe JSON with output_dir cleared ('' when written outside a recipe)",
    "recipe": "canonical recipe JSON (output_dir cleared), '{}' when written outside a recipe",
    "split": "split name",
    "shard_index": "block index k: the shard holds samples [k*S, (k+1)*S) of its split (S = samples_per_shard)",
    "part": "0, or p > 0 when the block rolled over by bytes into several files",
    "first_index": "split-level index of the shard's first sample",
    "n_samples": "number of sample groups",
    "variants": "JSON list of variant names every sample holds, 'orig' first",
    "stats": "JSON statistics of the shard's original samples (see docs/FORMAT.md)",
    "skeleton": "JSON of the first sample's skeleton",
    "skeletons": "JSON object: skeleton name -> number of samples (schema >= 1.1; a shard may mix topologies)",
    "attrs_sha256": "SHA-256 over every other attribute of every group (schema >= 1.2; see gttdata.shards.digest)",
}

#: Attributes of each ``samples/<index>`` group.
SAMPLE_ATTRS: dict[str, str] = {
    "name": "sample name, e.g. 'train/000017'",
    "motion_name": "source motion",
    "skeleton": "JSON of Skeleton.to_dict()",
    "meta": "JSON of CaptureSample.meta",
    "index": "split-level sample index",
}

#: Attributes of each ``samples/<index>/variants/<name>`` group.
VARIANT_ATTRS: dict[str, str] = {"meta": "JSON of the variant's CaptureSample.meta"}


def sample_group_name(index: int) -> str:
    """Name of the group of split-level sample ``index`` (``17 -> '000017'``)."""
    return f"{int(index):06d}"


def shard_file_name(shard_index: int, part: int = 0) -> str:
    """File name of block ``shard_index``, part ``part`` (``shard-00003.h5``, ``shard-00003.p1.h5``)."""
    if part == 0:
        return f"shard-{int(shard_index):05d}{SHARD_SUFFIX}"
    return f"shard-{int(shard_index):05d}.p{int(part)}{SHARD_SUFFIX}"


def dataset_kwargs(compression: str, shape: tuple[int, ...], *, compress: bool = True) -> dict:
    """``h5py.Group.create_dataset`` keywords for one per-sample array.

    Every array is one chunk (samples are read whole), checksummed with Fletcher-32 so a flipped bit is
    reported on read, and stored without modification times so identical content gives identical bytes.

    Args:
        compression: One of :data:`COMPRESSIONS`.
        shape: Array shape; empty arrays get no chunking or filters (HDF5 cannot chunk a zero extent).
        compress: False: checksum only, whatever ``compression`` says (see :attr:`FieldSpec.compress`).

    Returns:
        Keyword arguments (``chunks``, ``compression``, ``compression_opts``, ``shuffle``, ``fletcher32``,
        ``track_times``).
    """
    if compression not in COMPRESSIONS:
        raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
    kw: dict = {"track_times": False}
    if len(shape) == 0 or 0 in shape:
        return kw
    kw.update(chunks=tuple(int(s) for s in shape), fletcher32=True)
    if not compress:
        return kw
    if compression == "gzip":
        kw.update(compression="gzip", compression_opts=_GZIP_LEVEL, shuffle=True)
    elif compression == "lzf":
        kw.update(compression="lzf", shuffle=True)
    return kw


def check_schema_version(found: object, *, source: str) -> None:
    """Refuse a shard whose schema major version differs from :data:`SCHEMA_VERSION`'s.

    Args:
        found: The file's ``schema_version`` attribute (None when absent).
        source: File name for the message.

    Raises:
        ShardFormatError: Missing, malformed, or unknown major version.
    """
    if isinstance(found, bytes):
        found = found.decode()
    if found is None:
        raise ShardFormatError(f"{source}: root attribute 'schema_version' is missing; not a gttdata shard")
    major = str(found).split(".")[0]
    if not major.isdigit():
        raise ShardFormatError(
            f"{source}: schema_version: expected 'MAJOR.MINOR' like {SCHEMA_VERSION!r}, found {found!r}"
        )
    if major != SCHEMA_VERSION.split(".")[0]:
        raise ShardFormatError(
            f"{source}: schema_version: this gttdata reads major version {SCHEMA_VERSION.split('.')[0]}.x, "
            f"found {found!r}; regenerate the dataset or use a gttdata release that wrote it"
        )
