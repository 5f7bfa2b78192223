"""Errors a user can cause; the command line prints their message and exits 2."""


class UserError(Exception):
    """Bad input from the user: printed as one line, never as a traceback."""


class SceneError(UserError):
    """A scene file that cannot be rendered; the message names file, key and expectation."""

    def __init__(self, path: str, key: str, message: str):
        self.path, self.key = path, key
        where = f"{path}: {key}: " if key else f"{path}: "
        super().__init__(where + message)


#: The longest message printed: a huge list or path is cut, not printed whole.
MESSAGE_LIMIT = 600


def one_line(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """``text`` as one printable line: control characters escaped, cut to ``limit`` characters.

    A newline in a key or a file name must not split a message, and a value of
    200,000 elements must not make a line of 600 KB.
    """
    # Lone surrogates (the bytes of a file name that is not UTF-8) are not printable either.
    out = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                  for c in text)
    if len(out) > limit:
        out = out[:limit - 40] + f"... ({len(out):,} characters in all)"
    return out
