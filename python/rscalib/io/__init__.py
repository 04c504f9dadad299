"""Files in and out: videos and image folders, targets, camera files, result.json."""
