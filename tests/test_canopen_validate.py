"""hil.canopen.validate: each range on its boundary, the message naming the value as it is shown."""

from __future__ import annotations

import pytest

from hil.canopen.errors import CanopenInputError
from hil.canopen.validate import integer, node_id, word16


def test_a_16_bit_word_on_its_boundaries():
    assert word16("controlword", 0) == 0 and word16("controlword", 0xFFFF) == 0xFFFF
    with pytest.raises(CanopenInputError, match=r"^controlword = 0x10000 is outside 0x0\.\.0xFFFF \(16-bit word\)$"):
        word16("controlword", 0x10000)
    with pytest.raises(CanopenInputError, match=r"^controlword = -0x1 is outside 0x0\.\.0xFFFF \(16-bit word\)$"):
        word16("controlword", -1)


def test_node_ids_1_to_127_and_what_is_not_an_int():
    assert node_id(1) == 1 and node_id(127) == 127
    for bad in (0, 128):
        with pytest.raises(CanopenInputError, match=rf"^node_id = {bad} is outside 1\.\.127$"):
            node_id(bad)
    with pytest.raises(CanopenInputError, match=r"must be an int in 1\.\.127, got bool"):
        node_id(True)
    with pytest.raises(CanopenInputError, match=r"must be an int in 1\.\.127, got float 1\.0"):
        node_id(1.0)
    assert integer("x", -5, -10, 10) == -5  # a decimal range shows negatives as they are
    with pytest.raises(CanopenInputError, match=r"^x = -11 is outside -10\.\.10$"):
        integer("x", -11, -10, 10)
