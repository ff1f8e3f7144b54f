"""The layout kernels between the project's (H, W, C) images and the networks' (C, H, W) tensors."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.runtime.layout import clip_with_window, to_channels_first, to_image_clipped


def test_channels_first_is_numpys_join_and_transpose_into_the_buffer_given():
    image = np.random.default_rng(0).normal(size=(37, 53, 7)).astype(np.float32)  # two parts: 3 and 4 channels
    buffer = np.full((7, 37, 53), np.nan, np.float32)
    out = to_channels_first([image[..., :3], image[..., 3:]], buffer)
    assert out is buffer and np.array_equal(out, image.transpose(2, 0, 1))
    assert np.array_equal(to_channels_first([image[:, ::-1]]), np.ascontiguousarray(image[:, ::-1].transpose(2, 0, 1)))
    with pytest.raises(ValueError, match=r"\(7, 37, 53\)"):
        to_channels_first([image], np.empty((7, 53, 37), np.float32))


def test_image_clipped_is_the_transposed_output_clipped_to_0_1():
    planes = np.random.default_rng(1).normal(0.5, 0.6, size=(3, 29, 41)).astype(np.float32)
    image = to_image_clipped(planes)
    assert image.shape == (29, 41, 3) and image.flags.c_contiguous
    assert np.array_equal(image, np.clip(planes.transpose(1, 2, 0), 0.0, 1.0))
    assert image.min() == 0.0 and image.max() == 1.0, "the fixture reaches past both ends"


def test_channels_first_reads_a_window_of_a_packed_frame_in_place():
    """A window of channels 3..5 of a packed (H, W, 15) buffer, a view with a row stride of 15 floats a pixel, laid
    out as its contiguous copy's transpose."""
    packed = np.random.default_rng(3).random((40, 50, 15), dtype=np.float32)
    window = packed[7:31, 12:45, 3:6]
    assert not window.flags.c_contiguous
    assert np.array_equal(to_channels_first([window, packed[7:31, 12:45, 9:10]]),
                          np.concatenate([window, packed[7:31, 12:45, 9:10]], -1).transpose(2, 0, 1))


def test_clip_with_window_writes_the_planes_over_their_window_and_clips_the_rest_in_place():
    rng = np.random.default_rng(4)
    image = rng.normal(0.5, 0.6, size=(30, 44, 3)).astype(np.float32)
    planes = rng.normal(0.5, 0.6, size=(3, 12, 20)).astype(np.float32)
    expected = image.copy()
    expected[9:21, 16:36] = planes.transpose(1, 2, 0)
    out = clip_with_window(image, planes, top=9, left=16)
    assert out is image and np.array_equal(image, np.clip(expected, 0.0, 1.0))
    assert np.array_equal(clip_with_window(image.copy(), np.empty((3, 0, 0), np.float32)), image)
    with pytest.raises(ValueError, match=r"do not lie"):
        clip_with_window(image, planes, top=20, left=16)  # rows 20..31 of 30


def test_clip_with_window_takes_the_planes_only_in_the_blocks_where_says():
    """Per 4 x 4 block of the window (an LR pixel of a 4x network) ``where`` says whether the planes or the image's
    own pixels go there; both clipped to [0, 1]; a ``where`` of another shape is refused."""
    rng = np.random.default_rng(5)
    image = rng.normal(0.5, 0.6, size=(30, 44, 3)).astype(np.float32)
    planes = rng.normal(0.5, 0.6, size=(3, 12, 20)).astype(np.float32)
    where = rng.random((3, 5)) > 0.5
    expected = image.copy()
    window = expected[8:20, 12:32]
    taken = np.repeat(np.repeat(where, 4, 0), 4, 1)
    window[taken] = planes.transpose(1, 2, 0)[taken]
    out = clip_with_window(image, planes, top=8, left=12, where=where, scale=4)
    assert np.array_equal(out, np.clip(expected, 0.0, 1.0)) and 0 < where.sum() < where.size
    with pytest.raises(ValueError, match=r"one flag per 4x4 block"):
        clip_with_window(image, planes, top=8, left=12, where=where[:2], scale=4)


def test_the_history_feeds_parts_join_to_the_history_it_gives():
    """HistoryFeed.parts (what the upscaler lays out channels first) holds the channels of HistoryFeed's history."""
    from volsr_core.sr.history import HistoryFeed
    from volsr_core.sr.network_config import NetworkConfig

    rng = np.random.default_rng(2)
    colour, motion = rng.random((12, 10, 3), dtype=np.float32), rng.normal(0, 0.5, (12, 10, 2)).astype(np.float32)
    config = NetworkConfig(scale=4, taau_base=True, taau_aux=True)
    joined, parted = HistoryFeed(config), HistoryFeed(config)
    for jitter in ((0.1, -0.2), (-0.3, 0.25)):
        history, parts = joined(colour, motion, jitter), parted.parts(colour, motion, jitter)
        assert history.shape == (48, 40, 7) and [p.shape[2] for p in parts] == [3, 4]
        assert np.array_equal(to_channels_first(parts), history.transpose(2, 0, 1))
    assert HistoryFeed(NetworkConfig(scale=4)).parts(colour, motion, (0.0, 0.0)) is None
