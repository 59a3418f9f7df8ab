"""belt-tracker: poses of parts on a conveyor belt from one fixed camera."""

import os

__version__ = "0.1.0"

# OpenCV and FFmpeg print their own warnings for inputs the tracker reports itself in one line
# (a missing camera, an unreadable video); set before cv2 is first imported. A user's own
# setting wins, e.g. OPENCV_LOG_LEVEL=INFO to see them while debugging a camera.
os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
