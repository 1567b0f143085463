"""Wire-format codecs: bytes in, typed samples and counted errors out (no I/O, no ROS).

Modules
-------
biotac_spi
    BioTac SPI command bytes, reply words, frame patterns and the frame decoder.
bridge_serial
    Our USB-serial bridge framing that carries BioTac frames (CRC-32).
cdr
    A body part's ``SkinPartFrames`` read from and written as its serialised (CDR) bytes, in one compiled pass.
skin
    Skin-cell samples and their payload layout (shared by CAN and serial).
skin_can
    Our CAN layout for skin cells (python-can messages).
skin_serial
    Our serial framing for skin cells (CRC-32).
framing
    CRC, sequence tracking and the resynchronising stream decoder.
fuzz
    Fuzzers for all of the above (``tactile fuzz``).

See docs/protocols.md for the wire formats.
"""

__all__: list[str] = []
