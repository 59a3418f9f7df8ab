"""Recording every frame and result to MCAP, and replaying recordings bit-exactly.

- ``schemas``: topics, JSON schemas (Foxglove's ``foxglove.*`` types and our own) and message encoders.
- ``mcapio``: a chunked MCAP writer that flushes each chunk to the OS, and a reader that tolerates truncation.
- ``writer``: the recorder, a ``Sink`` with its own threads and a bounded queue.
- ``source``: ``McapSource``, a recording as a frame source (with its calibration and configuration).
- ``replay``: re-running the pipeline on a recording and comparing with the poses logged live.
"""
