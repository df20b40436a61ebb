"""
A study's results table: DIR/results.parquet, a Parquet dataset of one file per chunk.

Each chunk of points is written whole, to a hidden file renamed into place, so the table
(pyarrow.parquet.read_table or pandas.read_parquet of DIR/results.parquet) holds at any
moment every chunk finished so far and nothing half-written, and Ctrl-C or a crash loses
only the chunks in flight. DIR/study.json records the study file's SHA-256 and the chunk
size: a resumed run computes exactly the chunks missing, or refuses another study's table.
"""

import json
import os
import pathlib

import pyarrow as pa
import pyarrow.parquet as pq


class ResultsError(ValueError):
    """An output folder that cannot take this study's results (the message says why)."""


class Results:
    """The results of one study in one folder: which chunks are done, writing one more."""

    def __init__(self, out_dir, study, chunk_points, resume=False):
        """
        Open out_dir for study, in chunks of chunk_points points.

        :param resume: continue a table of this study (else out_dir must hold none)
        :raises ResultsError: a table already there without resume, or one of another study
            or chunk size with it
        """
        self.folder = pathlib.Path(out_dir)
        self.table_dir = self.folder / 'results.parquet'
        self.chunk_points, self.size = int(chunk_points), study.size
        manifest = self.folder / 'study.json'
        wanted = {'study': study.name, 'sha256': study.sha256, 'points': study.size,
                  'chunk_points': self.chunk_points}
        if manifest.exists() or self.table_dir.exists():
            if not resume:
                raise ResultsError(f'{self.folder} already holds a results table: --resume '
                                   'continues it, or choose another --out')
            try:
                found = json.loads(manifest.read_text())
            except (OSError, ValueError) as exc:
                raise ResultsError(f'{manifest}: unreadable ({exc}): cannot resume') from None
            if found != wanted:
                raise ResultsError(f'{self.folder} holds the results of another study or '
                                   f'chunking ({found}); this run is {wanted}')
        self.table_dir.mkdir(parents=True, exist_ok=True)
        _replace_text(manifest, json.dumps(wanted, indent=1) + '\n')

    @property
    def chunks(self):
        """Return the number of chunks of the study."""
        return -(-self.size // self.chunk_points)

    def bounds(self, index):
        """Return (start, stop) of chunk index's points."""
        start = index * self.chunk_points
        return start, min(start + self.chunk_points, self.size)

    def done(self):
        """Return the chunk indices already in the table."""
        return {int(p.stem.split('-')[1]) for p in self.table_dir.glob('chunk-*.parquet')}

    def missing(self):
        """Return the chunk indices still to compute, in order."""
        done = self.done()
        return [i for i in range(self.chunks) if i not in done]

    def write(self, index, columns):
        """Write chunk index's columns ({name: (k,) values}) as one file, atomically."""
        final = self.table_dir / f'chunk-{index:08d}.parquet'
        hidden = self.table_dir / f'.chunk-{index:08d}.parquet.tmp'
        pq.write_table(pa.table(columns), hidden)
        os.replace(hidden, final)

    def table(self):
        """Return the table of every chunk written, in point order (None: none yet)."""
        return _concatenated(self.table_dir)


def read_results(out_dir, study):
    """
    Return {column: (P,) numpy array} of study's whole table in out_dir.

    :raises ResultsError: no table there, one of another study, or not yet whole
    """
    folder = pathlib.Path(out_dir)
    try:
        found = json.loads((folder / 'study.json').read_text())
    except (OSError, ValueError) as exc:
        raise ResultsError(f'{folder}: no results table of a study here ({exc})') from None
    if not isinstance(found, dict) or found.get('sha256') != study.sha256:
        raise ResultsError(f'{folder} holds the results of another study or of another '
                           f'version of {study.source} ({found!r:.80})')
    table = _concatenated(folder / 'results.parquet')
    rows = 0 if table is None else table.num_rows
    if rows != study.size:
        raise ResultsError(f'{folder} holds {rows} of {study.size} points: finish it with '
                           'tentacle-sweep --resume')
    return {name: table.column(name).to_numpy() for name in table.column_names}


def _concatenated(table_dir):
    files = sorted(table_dir.glob('chunk-*.parquet'))
    return pa.concat_tables([pq.read_table(f) for f in files]) if files else None


def _replace_text(path, text):
    hidden = path.with_name(f'.{path.name}.tmp')
    hidden.write_text(text)
    os.replace(hidden, path)
