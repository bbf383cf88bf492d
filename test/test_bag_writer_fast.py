"""BagWriter's chunk writer against the mcap package's Writer: the same file, byte for byte."""

import io
import random

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import pytest

from tskf_ros.bag.writer import _ChunkWriter


def write(cls, seed, chunk_size, compression):
    """Write the same random file (schemas, channels, messages, flushes) with cls."""
    rng = random.Random(seed)
    out = io.BytesIO()
    w = cls(out, chunk_size=chunk_size, compression=compression, enable_crcs=True,
            enable_data_crcs=True)
    w.start(profile='ros2', library='test')
    schemas = [w.register_schema(f'p/msg/T{i}', 'ros2msg', b'float64 x') for i in range(2)]
    channels = [w.register_channel(f'/t{i}', 'cdr', schemas[i % 2], {'k': str(i)})
                for i in range(5)]
    t = 10 ** 18
    for seq in range(3000):
        t = max(0, t + rng.randrange(-10 ** 6, 10 ** 7))     # out of order at times
        w.add_message(rng.choice(channels[:4]), t, rng.randbytes(rng.randrange(0, 90)),
                      t + rng.randrange(0, 5), seq)
        if rng.random() < 0.002:
            w.flush()
    w.finish()
    return out.getvalue()


@pytest.mark.parametrize('compression', [CompressionType.NONE, CompressionType.ZSTD])
@pytest.mark.parametrize('chunk_size', [1, 700, 768 * 1024])
def test_the_chunk_writer_writes_what_the_mcap_writer_writes(chunk_size, compression):
    """Chunks, message indexes, CRCs, statistics (a channel without messages too)."""
    ours = write(_ChunkWriter, chunk_size, chunk_size, compression)
    assert ours == write(Writer, chunk_size, chunk_size, compression)
    reader = make_reader(io.BytesIO(ours), validate_crcs=True)
    stats = reader.get_summary().statistics
    assert stats.message_count == 3000 and 5 not in stats.channel_message_counts
    assert sum(1 for _ in reader.iter_messages()) == 3000


def test_an_empty_file_is_the_same_too():
    def empty(cls):
        out = io.BytesIO()
        w = cls(out, compression=CompressionType.NONE, enable_data_crcs=True)
        w.start(profile='ros2', library='test')
        w.register_channel('/t', 'cdr', w.register_schema('p/msg/T', 'ros2msg', b''))
        w.finish()
        return out.getvalue()
    assert empty(_ChunkWriter) == empty(Writer)
