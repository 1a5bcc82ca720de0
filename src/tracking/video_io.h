// Video input and output for the registration: FFmpeg (libavformat/libavcodec/
// libswscale) for mp4/mkv/avi files and OpenCV for folders of numbered images.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace arreg {

struct VideoReaderOptions {
  // Decoder threads; 1 (default) keeps timings single-threaded, 0 lets FFmpeg choose.
  int decode_threads = 1;
  // Skip H.264/HEVC's in-loop deblocking filter: faster decoding, but frames
  // differ from the encoder's and the error builds up until the next key frame.
  // Default false (exact frames).
  bool skip_loop_filter = false;
  // Frame rate reported for image-folder sequences, in frames per second (default 25).
  double image_sequence_fps = 25.0;
  // What a damaged frame in the middle of a file becomes (a frame the decoder flags as
  // corrupt, or a packet it refuses): kRepeatLastGood (default) returns the last good frame
  // in its place, so frame indices stay those of the file (and of any ground truth), lists it
  // in damaged_frames() and warns once per run of damaged frames; kStop ends the video there
  // as if the file were truncated.
  enum class Damaged { kRepeatLastGood, kStop };
  Damaged damaged = Damaged::kRepeatLastGood;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Reads a video file or an image folder frame by frame.
//
// Errors: a file that cannot be opened, holds no video stream, uses a codec
// this FFmpeg cannot decode, or whose first frame does not decode throws
// arreg::Error naming the file (and the frame). A file that breaks off later
// (truncated, unreadable) is read up to the last good frame: Read() returns
// false there, a warning names the file and frame, `truncated()` turns true and
// frame_count() is lowered to the frames actually decoded. Damaged frames in
// the middle (corrupt packets, a lost key frame) are replaced by the last good
// frame and listed (VideoReaderOptions::damaged).
class VideoReader {
 public:
  VideoReader();
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  // `path` is a video file or a directory of .png/.jpg/.jpeg/.bmp/.tif/.tiff
  // images (sorted by name). Decodes the first frame to make sure it can.
  void Open(const std::string& path, const VideoReaderOptions& options = {});
  void Close();
  bool is_open() const;
  const std::string& path() const;
  bool is_image_sequence() const;

  // Number of frames: the container's count (or packets counted at Open when
  // the container has none), lowered when the stream turns out shorter.
  int frame_count() const;
  double fps() const;
  int width() const;
  int height() const;
  // Index of the frame the next Read()/ReadGray() returns.
  int next_frame_index() const;
  // True once a read error or an early end of stream ended the video.
  bool truncated() const;
  // Indices of the frames returned so far that were damaged in the file and
  // replaced by the last good frame (ascending).
  const std::vector<int>& damaged_frames() const;

  // Next frame as 8-bit BGR (CV_8UC3). False at the end (or the last good frame).
  bool Read(cv::Mat* bgr);
  // Next frame as 8-bit grey (CV_8UC1). For YUV streams this is the luma plane
  // itself (limited-range luma stretched to 0..255), with no colour conversion.
  bool ReadGray(cv::Mat* gray);
  // Positions the reader so that the next Read() returns frame `frame`
  // (0-based). Throws arreg::Error when `frame` is out of range.
  void Seek(int frame);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct VideoWriterOptions {
  // Constant rate factor of x264 (0 lossless .. 51 worst; default 18, visually lossless).
  int crf = 18;
  // x264 speed preset (default "veryfast").
  std::string preset = "veryfast";
  // x264 tuning, e.g. "zerolatency" (no frame delay: no lookahead, no B-frames); empty (the
  // default) keeps the preset's settings.
  std::string tune;
  // FFmpeg encoder name (default "libx264").
  std::string codec = "libx264";
  // Pixel format of the encoded stream (default "yuv420p", which players expect).
  std::string pixel_format = "yuv420p";
  // Encoder threads; 0 (default) lets FFmpeg choose.
  int encode_threads = 0;
  // Put the mp4 index at the front so players can start before the end (default true).
  bool faststart = true;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Writes frames into a video file; the container follows the extension of the
// path (.mp4, .mkv, .avi). The file appears under its name only after Close().
class VideoWriter {
 public:
  VideoWriter();
  // Without Close(), the partial temporary file is removed.
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  void Open(const std::string& path, int width, int height, double fps,
            const VideoWriterOptions& options = {});
  // `image` is CV_8UC3 (BGR) or CV_8UC1 (grey), of the size given to Open().
  void Write(const cv::Mat& image);
  // Flushes the encoder, finishes the container and renames it into place.
  void Close();
  bool is_open() const;
  int frames_written() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arreg
