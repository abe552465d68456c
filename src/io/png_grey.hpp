// A fast path for the commonest image file of a replay: an 8-bit grey, non-interlaced PNG (every EuRoC,
// TUM-VI and rendered loopgate image). The zlib stream is inflated in one call by libdeflate (Debian
// libdeflate-dev), which is 1.5-2x faster than zlib's streaming inflate that OpenCV's libpng decoder uses,
// and the rows are unfiltered here (PNG filter types 0-4, ISO/IEC 15948 § 9). Decoding was a third of the CPU
// time of a rendered MH_05 run before this path.
//
// The fast path answers only what it is sure of. Anything else (another colour type or bit depth, interlace,
// a chunk that could change the pixels - tRNS, sBIT, PLTE..., a CRC or Adler-32 mismatch, a truncated or
// malformed file) returns an empty Mat, and the caller decodes with OpenCV as before: the pixels are those
// of cv::imdecode(IMREAD_UNCHANGED) in every case (tests/io_png_grey_test.cpp), and a damaged file gets
// OpenCV's verdict and loopgate's error message naming it, as before.
#pragma once

#include <cstddef>
#include <opencv2/core/mat.hpp>

namespace loopgate {

// The image of an 8-bit grey non-interlaced PNG held in `bytes`, or an empty Mat when the file is not one or
// anything about it is unexpected (the caller then decodes it the general way). Thread-safe.
cv::Mat decode_png_grey8(const unsigned char* bytes, std::size_t size);

}  // namespace loopgate
