"""``tracker calibrate``: camera intrinsics from chessboard views, the belt pose, and their quality reports."""
