"""drpt.render.deferred: a dataclass field computed on its first read, once; pickled and
copied as its value."""

import copy
import dataclasses
import pickle

import pytest

from drpt.render.deferred import DeferredField, Later


@dataclasses.dataclass
class Result:
    a: int
    b: list = DeferredField()
    c: list | None = DeferredField(default=None)


def test_a_field_without_default_is_required_and_one_with_it_defaults():
    with pytest.raises(TypeError):
        Result(1)  # (b has no default)
    r = Result(1, [2])
    assert r.b == [2] and r.c is None
    assert [f.name for f in dataclasses.fields(Result)] == ["a", "b", "c"]


def test_a_later_value_is_computed_on_the_first_read_only():
    calls = []
    r = Result(1, Later(lambda: calls.append(1) or [len(calls)]))
    assert calls == []
    assert r.b == [1] and r.b == [1] and calls == [1]
    r.b = [5]  # a plain value assigned is stored as is
    assert r.b == [5]
    r.c = Later(lambda: "c")
    assert r.c == "c"


def test_pickle_copy_equality_and_repr_see_the_value():
    calls = []
    r = Result(1, Later(lambda: calls.append(1) or [7]))
    back = pickle.loads(pickle.dumps(r))
    assert calls == [1] and back.b == [7] and back.__dict__["_b"] == [7]
    assert copy.deepcopy(Result(1, Later(lambda: [8]))).b == [8]
    assert Result(1, Later(lambda: [7])) == r and "b=[7]" in repr(r)
    assert dataclasses.replace(r, a=2).b == [7] and len(calls) == 1


def test_negative_control_without_the_descriptor_the_later_itself_is_read():
    # without the descriptor, a Later assigned is what the field reads back
    @dataclasses.dataclass
    class Plain:
        b: object = None

    p = Plain(Later(lambda: [1]))
    assert isinstance(p.b, Later)
