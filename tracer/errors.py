"""Errors a user can cause; the command line prints their message and exits 2."""


class UserError(Exception):
    """Bad input from the user: printed as one line, never as a traceback."""


class SceneError(UserError):
    """A scene file that cannot be rendered; the message names file, key and expectation."""

    def __init__(self, path: str, key: str, message: str):
        self.path, self.key = path, key
        where = f"{path}: {key}: " if key else f"{path}: "
        super().__init__(where + message)
