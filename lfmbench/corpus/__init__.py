"""The lfmbench radiance corpus: OpenEXR files + JSON metadata + a SHA-256 manifest.

This package defines the on-disk format specified in ``docs/guide/corpus-format.md`` (and summarised in
``docs/guide/contracts.md`` section 2) and everything that touches it. Data flow one way through its modules
(each imports only those above it):

* :mod:`~lfmbench.corpus.errors`: :class:`CorpusError` and its subclasses (each message names the file at fault);
* :mod:`~lfmbench.corpus.naming`: format name and versions, file names, header attributes, channel names;
* :mod:`~lfmbench.corpus.storage`: how radiance layers are stored (:class:`Storage`: HALF x per-layer 2^e,
  mantissa rounding, codecs; :func:`store_layer`);
* :mod:`~lfmbench.corpus.exr_encode`, :mod:`~lfmbench.corpus.exr`: low-level EXR encoding / decoding through the
  OpenEXR 3.x Python API (``OpenEXR.File`` / ``OpenEXR.Part``): :func:`encode_static_exr`,
  :func:`encode_lights_exr`, :func:`encode_aux_exr`, :func:`read_exr`;
* :mod:`~lfmbench.corpus.meta`: :func:`validate_meta` (consistency checks of a scene's ``meta.json``: timing,
  bands, groups, camera), manifest and ``splits.json`` checks, :func:`make_splits`, :func:`sha256_file`;
* :mod:`~lfmbench.corpus.window_layers`: static window layers (a static group over a named union of capture
  windows, e.g. a chopped sensor's sub-windows): :func:`parse_layers` (the one rule of what a layer may be), file
  names and the scene's ``window_layers.json``;
* :mod:`~lfmbench.corpus.reader`: :class:`Corpus`, the reader (lazy: one file per frame and light group is
  decoded only when asked for, with a small cache so that reading ``short`` then ``long`` decodes the file once);
* :mod:`~lfmbench.corpus.writer`: :class:`CorpusWriter`: a manifest that is rewritten atomically after each
  finished scene, resume support (:meth:`CorpusWriter.is_complete`), the one-writer lock;
* :mod:`~lfmbench.corpus.scene_files`: :func:`encode_scene`, :func:`write_files` (atomic writes: temporary name
  in the same directory, then :func:`os.replace`); :class:`ThreadedSceneWriter` (encoding and writing in a worker
  thread while the next frame renders);
* :mod:`~lfmbench.corpus.validate`: :func:`validate_corpus`, a full check of a corpus (missing files,
  checksums, channels, NaN/inf/negative radiance, metadata consistency), used by ``lfmbench validate``.

Every name is importable from ``lfmbench.corpus`` itself. A test that replaces a function used inside the
package patches it in the module that uses it (e.g. ``lfmbench.corpus.reader.read_exr``).

Units: spectral radiance in W sr^-1 m^-2 nm^-1, wavelengths in nm, times in s, depth in m, bounding boxes in
pixels as half-open ``(y0, x0, y1, x1)`` (rows y0..y1-1, columns x0..x1-1).

Timing convention (``docs/guide/contracts.md`` section 1): frame n starts at n / fps; the long window is
``[t_n, t_n + T_L)``, the short window is centred in it, and flickering groups are stored in K equal bins over
the capture window ``[t_n, t_n + T_L + readout_s)``.

References: OpenEXR file layout and multi-part files, https://openexr.com/en/latest/TechnicalIntroduction.html
(data window / display window, part names); SHA-256, FIPS PUB 180-4.
"""
from lfmbench.check import check_scene_id
from lfmbench.corpus.errors import (CorpusChannelError, CorpusError, CorpusFileError, CorpusNotFoundError,
                                    CorpusLockedError, CorpusValueError, CorpusWriteError)
from lfmbench.corpus.exr import ExrPart, check_exr_header, layer_scale, read_exr
from lfmbench.corpus.exr_encode import SteadyBins, encode_aux_exr, encode_lights_exr, encode_static_exr, split_steady
from lfmbench.corpus.meta import (LIGHT_KINDS, SPECTRUM_MODELS, TIMING_RTOL, check_splits, inside_root, make_splits,
                                  load_meta, manifest_entry_errors, sha256_file, validate_meta)
from lfmbench.corpus.naming import (ATTR, AUX_CHANNELS, EMPTY_PART, FORMAT_NAME, FORMAT_VERSION, MANIFEST_NAME,
                                    RADIANCE_MAX, RADIANCE_UNIT, READABLE_VERSIONS, SCENES_DIR, SPLITS_NAME,
                                    STATIC_WINDOWS, STEADY_PREFIX, band_channel, bin_channels, bin_prefix, frame_dir,
                                    group_storage, light_part_name, parse_light_part, static_channels, steady_channels,
                                    STATIC_BINS_VERSION, static_edges, static_layers, window_bin_weights)
from lfmbench.corpus.reader import Corpus
from lfmbench.corpus.window_layers import LAYERS_FILE, layer_relpath, parse_layers, read_layers_file
from lfmbench.corpus.storage import (COMPRESSIONS, DEFAULT_STORAGE, EXTRA_COMPRESSIONS, HALF_MAX, HALF_MIN_NORMAL,
                                     HALF_PRECISION_RANGE_LOG2, HALF_UNDERFLOW_ERROR_FRACTION, MANTISSA_BITS,
                                     SCALE_EXP_RANGE, STORAGES, LayerStore, Storage, StorageStats, resolve_storage,
                                     float_to_half, round_mantissa, scale_attr, scale_exponent, store_layer)
from lfmbench.corpus.validate import ValidationReport, validate_corpus
from lfmbench.corpus.scene_files import ThreadedSceneWriter, encode_scene, write_files
from lfmbench.corpus.writer import LOCK_NAME, CorpusLock, CorpusWriter, prune_scene_dir
from lfmbench.fileio import TMP_PREFIX, atomic_write_bytes, atomic_write_json

__all__ = [
    "LAYERS_FILE", "layer_relpath", "parse_layers", "read_layers_file",
    "FORMAT_NAME", "FORMAT_VERSION", "STATIC_BINS_VERSION", "static_edges", "static_layers", "window_bin_weights",
    "READABLE_VERSIONS", "STATIC_WINDOWS", "AUX_CHANNELS", "HALF_MAX",
    "HALF_MIN_NORMAL", "HALF_UNDERFLOW_ERROR_FRACTION", "RADIANCE_UNIT", "COMPRESSIONS", "STORAGES",
    "DEFAULT_STORAGE", "Storage", "resolve_storage", "round_mantissa", "scale_exponent", "store_layer",
    "scale_attr", "LayerStore", "StorageStats",
    "CorpusError", "CorpusNotFoundError", "CorpusFileError", "CorpusChannelError", "CorpusValueError",
    "CorpusWriteError", "band_channel", "bin_prefix", "static_channels", "bin_channels", "frame_dir",
    "group_storage", "encode_static_exr", "encode_lights_exr", "encode_aux_exr", "read_exr", "sha256_file",
    "atomic_write_bytes", "atomic_write_json", "make_splits", "validate_meta", "load_meta", "Corpus", "CorpusWriter",
    "ValidationReport", "validate_corpus", "encode_scene", "write_files", "prune_scene_dir", "ExrPart",
    "check_scene_id", "manifest_entry_errors", "inside_root", "check_splits", "RADIANCE_MAX",
    "ThreadedSceneWriter", "float_to_half", "CorpusLockedError", "CorpusLock", "LOCK_NAME", "check_exr_header",
    "split_steady", "SteadyBins", "STEADY_PREFIX", "steady_channels", "light_part_name", "parse_light_part",
]
