"""The buffers with room one stage leaves for the next (`volseg._buffers`): what each
layout test accepts, and that it refuses every array whose memory it does not own."""

import numpy as np

from volseg._buffers import margin_owner, padded_size, room_to_pad, with_room


def test_with_room_starts_a_buffer_that_room_to_pad_finds():
    for shape in [(3, 4, 5), (1, 1, 1), (2, 1, 7)]:
        field = with_room(shape)
        buffer = room_to_pad(field)
        assert field.shape == shape and field.dtype == np.float64
        assert buffer is not None and buffer.size == padded_size(shape)
        assert np.shares_memory(buffer, field) and buffer.base is field.base


def test_room_to_pad_refuses_what_it_cannot_pad_in():
    shape = (4, 3, 5)
    big = np.empty(padded_size(shape) + 3)
    tight = np.empty(padded_size(shape) - 1)
    refused = [
        np.empty(shape),                                     # owns its memory: no room
        tight[:60].reshape(shape),                           # a buffer one value short
        big[1:61].reshape(shape),                            # not at the buffer's start
        np.empty(padded_size(shape), np.float32)[:60].reshape(shape),
        big[:60].reshape(shape[::-1]).transpose(2, 1, 0),   # not C order
        big[:60].reshape(12, 5),                             # not 3-D
        np.empty((padded_size(shape), 2))[:, 0][:60].reshape(shape),  # strided buffer
    ]
    for k, case in enumerate(refused):
        assert room_to_pad(case) is None, k
    assert room_to_pad(big[:60].reshape(shape)) is not None


def test_margin_owner_finds_only_the_interior_of_a_one_voxel_wider_buffer():
    buffer = np.empty((6, 5, 7))
    assert margin_owner(buffer[1:-1, 1:-1, 1:-1]) is buffer
    refused = [buffer, buffer[:-2, 1:-1, 1:-1], buffer[1:-1, 1:-1, 2:],
               buffer[1:-1, 1:-1, 1:-1][::-1], np.empty((6, 5, 7), np.float32)[1:-1, 1:-1, 1:-1],
               np.empty((6, 5, 7, 1))[1:-1, 1:-1, 1:-1, 0],
               np.asfortranarray(buffer)[1:-1, 1:-1, 1:-1]]
    for k, case in enumerate(refused):
        assert margin_owner(case) is None, k
