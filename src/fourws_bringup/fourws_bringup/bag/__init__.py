"""Bags of fourws runs: rosbag2 layout (``metadata.yaml`` + one MCAP file), read, recover.

Layout written by :class:`~fourws_bringup.bag.writer.BagWriter` (the recorder node's
storage), the same as rosbag2's MCAP storage plugin writes on Jazzy, so ``rosbags`` and the
MCAP tools read it::

    <bag>/metadata.yaml        rosbag2_bagfile_information, version 9
    <bag>/<bag>_0.mcap         profile ros2; schemas ros2msg; channels cdr; zstd chunks

One module per job (import from them; this package re-exports nothing):

- ``errors``: :class:`BagError`, whose message names the file and what is wrong;
- ``schema``: ``ros2msg`` schema text and RIHS01 type hashes of the installed interfaces,
  the stamp read straight from CDR bytes;
- ``metadata``: ``metadata.yaml`` (built, written) and QoS text as rosbag2 writes it,
  ``parse_offered_qos``;
- ``writer``: :class:`BagWriter`, chunk by chunk, durable after each chunk;
- ``reader``: ``resolve_mcap``, ``check_mcap``, :class:`McapBag`, :class:`ChannelInfo`;
- ``run_data``: :func:`read_run` into :class:`RunData` (per-step numpy arrays),
  ``drop_strays``, ``STEP_TOPICS``, rejection counts from /diagnostics;
- ``recovery``: ``recover`` a truncated file, ``recover_folder`` in place, ``in_bag_folder``.

The graph's topics, types and QoS are in ``fourws_common.topics``. No rclpy in this package:
mcap, mcap_ros2, numpy, yaml, ament_index_python (schema text) and rosbags (type hashes).
"""
