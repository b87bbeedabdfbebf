"""Tokenizer for drpt's text scene format, keeping 1-based line numbers.

Lexical rules
-------------
* Tokens are separated by whitespace.
* ``{`` and ``}`` are always tokens of their own, even when glued to a word:
  ``Group{`` is the two tokens ``Group`` and ``{``.
* ``#`` starts a comment that runs to the end of the line, wherever it is.
* ``//`` starts a comment to the end of the line when it begins a token (so a
  path such as ``dir//file.obj`` is kept intact).
* The file must be UTF-8 (a leading byte-order mark is ignored).
* Lines end at ``\n``, ``\r\n`` or ``\r`` only (:func:`split_lines`): other
  characters Python's ``str.splitlines`` breaks at (``\v``, ``\f``,
  ``\x1c``-``\x1e``, ``\x85``, ``\u2028``, ``\u2029``) are whitespace
  inside a line, so line numbers are those of editors and ``grep -n``.

:class:`TokenStream` adds the typed readers the parser needs (numbers,
vectors, counts); each raises :class:`~drpt.errors.SceneError` with the file
and line of the offending token.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import Loc, SceneError
from .files import read_bytes

# A decimal number: optional sign, digits with an optional fraction, optional
# exponent. Deliberately excludes "nan", "inf", hex and "1_000" (which Python's
# float() would accept).
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_INTEGER = re.compile(r"[+-]?\d+\Z")
_SPLIT = re.compile(r"[{}]|[^\s{}]+")


@dataclass(frozen=True)
class Token:
    text: str
    line: int


def split_lines(text: str) -> list[str]:
    """``text``'s lines, ended by ``\n``, ``\r\n`` or ``\r`` (like
    ``str.splitlines`` for those three; no other character ends a line)."""
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()
    return lines


def read_text(path: Path, *, ref: Loc | None = None, what: str = "file") -> str:
    """Read ``path`` as UTF-8 text; every failure becomes a :class:`SceneError`.

    ``ref`` is the place that named ``path``; a missing file, or one
    that is not a regular file (see :func:`drpt.scene.files.check_input`),
    is reported there. Invalid UTF-8 is reported at the bad byte's line in
    ``path`` itself. ``/dev/null`` reads as empty text.
    """
    data = read_bytes(path, ref=ref, what=what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        before = data[: e.start]
        line = before.count(b"\n") + before.count(b"\r") - before.count(b"\r\n") + 1
        raise SceneError(Loc(path, line), f"not valid UTF-8 text (byte 0x{data[e.start]:02x})") from None


def tokenize(text: str) -> list[Token]:
    """Split ``text`` into tokens following the module's lexical rules."""
    tokens: list[Token] = []
    for lineno, line in enumerate(split_lines(text), 1):
        hash_at = line.find("#")
        if hash_at >= 0:
            line = line[:hash_at]
        for m in _SPLIT.finditer(line):
            word = m.group()
            if word.startswith("//"):
                break
            tokens.append(Token(word, lineno))
    return tokens


def parse_number(text: str) -> float | None:
    """``float(text)`` if ``text`` is a plain finite decimal number, else ``None``."""
    if not _NUMBER.match(text):
        return None
    value = float(text)
    return value if math.isfinite(value) else None


class TokenStream:
    """Sequential access to a file's tokens with typed, located readers."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.tokens = tokenize(text)
        self.pos = 0
        self.last_line = max(1, len(split_lines(text)))

    # ------------------------------------------------------------ basics
    def error(self, line: int | None, message: str) -> SceneError:
        return SceneError(self.loc(line), message)

    def loc(self, line: int | None) -> Loc:
        """The place ``line`` of this file."""
        return Loc(self.path, line)

    def at_end(self) -> bool:
        return self.pos >= len(self.tokens)

    def peek(self) -> Token | None:
        return self.tokens[self.pos] if self.pos < len(self.tokens) else None

    def next(self, what: str) -> Token:
        """The next token; ``what`` names what was expected, for the EOF message."""
        if self.pos >= len(self.tokens):
            raise self.error(self.last_line, f"unexpected end of file: expected {what}")
        tok = self.tokens[self.pos]
        self.pos += 1
        return tok

    def expect(self, text: str, context: str) -> Token:
        tok = self.next(f"'{text}' {context}")
        if tok.text != text:
            raise self.error(tok.line, f"expected '{text}' {context}, found '{tok.text}'")
        return tok

    def word(self, what: str) -> Token:
        """A token that is not a brace (names, file names)."""
        tok = self.next(what)
        if tok.text in ("{", "}"):
            raise self.error(tok.line, f"expected {what}, found '{tok.text}'")
        return tok

    # ----------------------------------------------------------- numbers
    def number(self, what: str) -> float:
        tok = self.next(what)
        value = parse_number(tok.text)
        if value is None:
            raise self.error(tok.line, f"expected a finite number for {what}, found '{tok.text}'")
        return value

    def integer(self, what: str) -> int:
        tok = self.next(what)
        if not _INTEGER.match(tok.text):
            raise self.error(tok.line, f"expected an integer for {what}, found '{tok.text}'")
        return int(tok.text)

    def vec3(self, what: str) -> tuple[float, float, float]:
        return (self.number(f"{what} (x)"), self.number(f"{what} (y)"), self.number(f"{what} (z)"))
