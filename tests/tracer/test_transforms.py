"""to_world steps and frames, against Mitsuba's Transform4f."""

import numpy as np
import pytest

from whitted.tracer import transform as tf


@pytest.mark.parametrize("axis,angle", [((1, 0, 0), -90), ((0, 1, 0), 35), ((1, 2, 3), 123.4)])
def test_rotation_is_right_handed_like_mitsubas(mi, axis, angle):
    # The scene format normalises the axis; Mitsuba's rotate() expects a unit axis.
    ours = tf.rotate(axis, angle)
    unit = (np.asarray(axis) / np.linalg.norm(axis)).tolist()
    theirs = np.asarray(mi.ScalarTransform4f().rotate(unit, angle).matrix, dtype=np.float64)
    assert np.allclose(ours, theirs, atol=1e-6)


def test_rotation_about_z_turns_x_into_y():
    assert np.allclose(tf.apply_point(tf.rotate((0, 0, 1), 90), (1, 0, 0)), (0, 1, 0))


def test_look_at_matches_mitsubas_frame(mi):
    o, t, up = (1, 2, 3), (0, 0.5, -1), (0, 1, 0)
    theirs = np.asarray(mi.ScalarTransform4f().look_at(origin=o, target=t, up=up).matrix)
    assert np.allclose(tf.look_at(o, t, up), theirs, atol=1e-6)


def test_steps_compose_first_step_first():
    m = tf.compose([tf.scale(2), tf.translate((1, 0, 0))])
    assert np.allclose(tf.apply_point(m, (1, 0, 0)), (3, 0, 0))


def test_normals_transform_by_inverse_transpose():
    m = tf.scale((1, 4, 1))
    # The plane x + y = 0 has normal (1, 1, 0); scaled by 4 in y it becomes x + y/4 = 0.
    n = tf.apply_normal(m, (1, 1, 0))
    assert np.allclose(n / np.linalg.norm(n), np.array([1, 0.25, 0]) / np.linalg.norm([1, 0.25, 0]))
