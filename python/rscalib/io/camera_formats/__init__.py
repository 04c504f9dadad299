"""Camera files of other tools, one module per format family (docs/formats.md has the table of
formats, models and the consumer each was checked against):

- common.py   CameraFile, and CameraModel <-> OpenCV's (K, dist) that every format goes through
- opencv.py   OpenCV FileStorage YAML (read through cv2.FileStorage, the real consumer)
- kalibr.py   Kalibr camchain: read cam0; write with k3 refitted away (Kalibr's radtan has no k3)
- ros.py      ROS camera_info YAML (camera_calibration_parsers: plumb_bob, rational_polynomial, equidistant)
- mrcal.py    mrcal .cameramodel (LENSMODEL_OPENCV4/5/8, PINHOLE) and the detections as corners.vnl
- colmap.py   COLMAP cameras.txt (its pixel centres are at +0.5 px from OpenCV's)
- gyroflow.py Gyroflow lens profile JSON

`rscalib.io.cameras` is the front door: load_camera picks the reader, write_camera the writer.
"""
