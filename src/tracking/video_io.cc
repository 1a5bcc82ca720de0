#include "tracking/video_io.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libavutil/mem.h>
#include <libavutil/opt.h>
#include <libavutil/pixdesc.h>
#include <libswscale/swscale.h>
}

#include "core/error.h"
#include "core/file_util.h"
#include "core/log.h"

namespace arreg {
namespace fs = std::filesystem;

namespace {

std::string AvErrorString(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof(buf));
  return buf;
}

std::string FrameWhere(int frame) { return "frame " + std::to_string(frame); }

// FFmpeg prints straight to stderr by default; its messages about damaged
// streams are expected here (we report them ourselves), so they go to the
// debug log instead.
void FfmpegLogCallback(void* avcl, int level, const char* fmt, va_list vl) {
  if (level > AV_LOG_WARNING || GetLogLevel() > LogLevel::kDebug) return;
  char line[1024];
  int print_prefix = 1;
  av_log_format_line(avcl, level, fmt, vl, line, sizeof(line), &print_prefix);
  std::string text(line);
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  if (!text.empty()) LogMessage(LogLevel::kDebug, "ffmpeg: " + text);
}

// The largest single block FFmpeg may allocate. A damaged container can declare table sizes
// its file could never hold (an mp4 of 1.4 KB asked for 1.6 GB); with this cap the demuxer
// fails with ENOMEM, which is reported as a bad file. Real frames stay far below it: an 8K RGB
// frame is 100 MB.
constexpr size_t kFfmpegMaxAllocationBytes = size_t{256} << 20;

// Once per process: FFmpeg's log to ours, its allocation cap.
void InstallFfmpegSettings() {
  static std::once_flag once;
  std::call_once(once, [] {
    av_log_set_callback(FfmpegLogCallback);
    av_max_alloc(kFfmpegMaxAllocationBytes);
  });
}

bool IsImageFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".tif" ||
         ext == ".tiff";
}

// The value of one of a frame's colour fields as stored. The decoder copies them from the
// bitstream unchecked, so a damaged stream can leave a value outside the enumeration there, and
// reading such a field as its enum type is undefined behaviour.
template <class Enum>
int StoredValue(const Enum& field) {
  static_assert(sizeof(Enum) == sizeof(int), "FFmpeg's colour enums are int-sized");
  int value = 0;
  std::memcpy(&value, &field, sizeof(value));
  return value;
}

// Frames above kMaxPixelsFactor times the pixels the stream declares (at least kMinMaxPixels)
// are refused by the decoder (VideoReader::Impl::Open).
constexpr int64_t kMaxPixelsFactor = 4;
constexpr int64_t kMinMaxPixels = int64_t{64} * 64;

// The largest frame a video may have: 4096 x 4096 pixels (DCI 4K and every laparoscope's sensor
// fit). A damaged header can declare tens of megapixels in a stream of a few bytes, and FFmpeg
// decodes such frames already while probing the stream (avformat_find_stream_info), for about
// 0.3 s each; the probe's decoders refuse them, and a stream that declares more is refused.
constexpr int64_t kMaxFramePixels = int64_t{4096} * 4096;

int SwsColorspace(const AVFrame& f) {
  switch (StoredValue(f.colorspace)) {
    case AVCOL_SPC_BT709:
      return SWS_CS_ITU709;
    case AVCOL_SPC_BT2020_NCL:
    case AVCOL_SPC_BT2020_CL:
      return SWS_CS_BT2020;
    default:
      return SWS_CS_DEFAULT;
  }
}

bool FullRange(const AVFrame& f) { return StoredValue(f.color_range) == AVCOL_RANGE_JPEG; }

}  // namespace

void VideoReaderOptions::Check() const {
  ARREG_CHECK_INPUT(decode_threads >= 0, "", "VideoReaderOptions.decode_threads",
                    "must be >= 0 (0 = FFmpeg chooses), got ", decode_threads);
  ARREG_CHECK_INPUT(image_sequence_fps > 0 && std::isfinite(image_sequence_fps), "",
                    "VideoReaderOptions.image_sequence_fps", "must be > 0, got ",
                    image_sequence_fps);
}

void VideoWriterOptions::Check() const {
  ARREG_CHECK_INPUT(crf >= 0 && crf <= 51, "", "VideoWriterOptions.crf", "must be in 0..51, got ",
                    crf);
  ARREG_CHECK_INPUT(!codec.empty(), "", "VideoWriterOptions.codec", "must not be empty");
  ARREG_CHECK_INPUT(av_get_pix_fmt(pixel_format.c_str()) != AV_PIX_FMT_NONE, "",
                    "VideoWriterOptions.pixel_format", "unknown pixel format '", pixel_format, "'");
  ARREG_CHECK_INPUT(encode_threads >= 0, "", "VideoWriterOptions.encode_threads",
                    "must be >= 0, got ", encode_threads);
}

// ---------------------------------------------------------------------------
// VideoReader

struct VideoReader::Impl {
  std::string path;
  VideoReaderOptions options;
  bool open = false;
  int width = 0, height = 0, frame_count = 0;
  bool size_known = false;  // width and height are the first decoded frame's
  double fps = 0;
  int next_index = 0;  // index of the frame Read() returns next
  bool truncated = false;

  // Image folder.
  bool is_sequence = false;
  std::vector<std::string> image_files;

  // FFmpeg.
  AVFormatContext* format = nullptr;
  AVCodecContext* decoder = nullptr;
  AVPacket* packet = nullptr;
  AVFrame* frame = nullptr;
  SwsContext* sws = nullptr;
  int stream_index = -1;
  AVRational time_base{0, 1};
  int64_t start_pts = 0;
  bool frame_ready = false;  // `frame` holds frame `next_index`, not yet returned
  bool flushing = false;     // end of input was sent to the decoder
  bool finished = false;     // no more frames will come
  // Damaged frames (VideoReaderOptions::Damaged::kRepeatLastGood).
  AVFrame* last_good = nullptr;  // a reference to the last good frame decoded
  std::vector<int> damaged;      // indices of the frames stood in for
  int damaged_run_start = -1;    // first index of the current run of damaged frames, or -1
  cv::Mat limited_to_full_lut;

  ~Impl() { Release(); }

  void Release() {
    sws_freeContext(sws);
    sws = nullptr;
    av_frame_free(&frame);
    av_frame_free(&last_good);
    av_packet_free(&packet);
    avcodec_free_context(&decoder);
    avformat_close_input(&format);
    image_files.clear();
    open = false;
  }

  // Stops reading at frame `next_index`: later frames are given up.
  void StopWithWarning(const std::string& why) {
    finished = true;
    frame_ready = false;
    truncated = true;
    ARREG_LOG_WARNING(FormatErrorMessage(path, FrameWhere(next_index), why), "; using the ",
                      next_index, " frames before it");
    frame_count = next_index;
  }

  int64_t FrameIndexOf(int64_t pts) const {
    if (pts == AV_NOPTS_VALUE) return -1;
    return std::llround(static_cast<double>(pts - start_pts) * av_q2d(time_base) * fps);
  }

  bool RepeatDamaged() const {
    return options.damaged == VideoReaderOptions::Damaged::kRepeatLastGood;
  }

  // Puts the last good frame into `frame` in place of frame `next_index`. False
  // when there is none yet (the damage is in the first frame).
  bool StandIn() {
    if (last_good == nullptr) return false;
    av_frame_unref(frame);
    const int r = av_frame_ref(frame, last_good);
    ARREG_CHECK_INPUT(r >= 0, path, FrameWhere(next_index), "out of memory");
    if (damaged_run_start < 0) damaged_run_start = next_index;
    damaged.push_back(next_index);
    return true;
  }

  // One warning per run of damaged frames, when the run ends (a good frame or the end).
  void WarnDamagedRun() {
    if (damaged_run_start < 0) return;
    const int last = damaged.back();
    ARREG_LOG_WARNING(FormatErrorMessage(
        path,
        damaged_run_start == last
            ? FrameWhere(last)
            : "frames " + std::to_string(damaged_run_start) + "-" + std::to_string(last),
        "damaged (decode errors); the last good frame stands in"));
    damaged_run_start = -1;
  }

  void GoodFrame() {
    WarnDamagedRun();
    if (!RepeatDamaged()) return;
    if (last_good == nullptr) last_good = av_frame_alloc();
    av_frame_unref(last_good);
    if (av_frame_ref(last_good, frame) < 0) av_frame_free(&last_good);
  }

  // Decodes the next frame into `frame`. False at the end of the stream or, with
  // Damaged::kStop, at the first damaged frame (with a warning).
  bool DecodeNext() {
    if (finished) return false;
    for (;;) {
      int r = avcodec_receive_frame(decoder, frame);
      if (r == 0) {
        // The video's size is its first frame's (the camera's intrinsics belong to it); a
        // later frame of another size is damage (a corrupt header can announce a huge
        // frame, whose conversion would take seconds).
        const bool resized = size_known && (frame->width != width || frame->height != height);
        if (resized || (frame->flags & AV_FRAME_FLAG_CORRUPT) || frame->decode_error_flags) {
          if (RepeatDamaged() && StandIn()) return true;
          StopWithWarning(resized
                              ? "frame size changes from " + std::to_string(width) + "x" +
                                    std::to_string(height) + " to " + std::to_string(frame->width) +
                                    "x" + std::to_string(frame->height)
                              : std::string("damaged frame (decode errors)"));
          return false;
        }
        GoodFrame();
        return true;
      }
      if (r == AVERROR_EOF) {
        finished = true;
        WarnDamagedRun();
        if (next_index < frame_count) {
          StopWithWarning("stream ends early, " + std::to_string(frame_count) +
                          " frames announced (truncated file?)");
        }
        return false;
      }
      if (r != AVERROR(EAGAIN)) {
        if (RepeatDamaged() && StandIn()) return true;
        StopWithWarning("decode error: " + AvErrorString(r));
        return false;
      }
      if (flushing) {
        // The decoder wants input after the end of stream: treat as the end.
        finished = true;
        return false;
      }
      r = av_read_frame(format, packet);
      if (r < 0) {
        if (r != AVERROR_EOF) {
          ARREG_LOG_WARNING(
              FormatErrorMessage(path, FrameWhere(next_index), "read error: " + AvErrorString(r)));
          truncated = true;
        }
        avcodec_send_packet(decoder, nullptr);
        flushing = true;
        continue;
      }
      if (packet->stream_index != stream_index) {
        av_packet_unref(packet);
        continue;
      }
      r = avcodec_send_packet(decoder, packet);
      av_packet_unref(packet);
      if (r < 0 && r != AVERROR(EAGAIN)) {
        // One packet of a video stream holds one frame: it gets its stand-in now.
        if (RepeatDamaged() && StandIn()) return true;
        StopWithWarning("cannot decode packet: " + AvErrorString(r));
        return false;
      }
    }
  }

  // Makes `frame` hold frame `next_index`.
  bool EnsureFrame() {
    if (frame_ready) return true;
    frame_ready = DecodeNext();
    return frame_ready;
  }

  void OpenSequence(const std::string& dir) {
    is_sequence = true;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir, ec))
      if (entry.is_regular_file() && IsImageFile(entry.path()))
        image_files.push_back(entry.path().string());
    ARREG_CHECK_INPUT(!ec, dir, "", "cannot list directory: ", ec.message());
    ARREG_CHECK_INPUT(!image_files.empty(), dir, "",
                      "no images (.png .jpg .jpeg .bmp .tif .tiff) in this folder");
    std::sort(image_files.begin(), image_files.end());
    const cv::Mat first = cv::imread(image_files[0], cv::IMREAD_UNCHANGED);
    ARREG_CHECK_INPUT(!first.empty(), image_files[0], FrameWhere(0), "cannot read image");
    width = first.cols;
    height = first.rows;
    frame_count = static_cast<int>(image_files.size());
    fps = options.image_sequence_fps;
  }

  cv::Mat ReadImage(int flags) {
    const std::string& file = image_files[next_index];
    cv::Mat image = cv::imread(file, flags);
    ARREG_CHECK_INPUT(!image.empty(), file, FrameWhere(next_index), "cannot read image");
    ARREG_CHECK_INPUT(image.cols == width && image.rows == height, file, FrameWhere(next_index),
                      "image is ", image.cols, "x", image.rows, " but the sequence is ", width, "x",
                      height);
    if (image.depth() != CV_8U)
      image.convertTo(image, CV_8U, image.depth() == CV_16U ? 1.0 / 257 : 1);
    return image;
  }

  // avformat_find_stream_info with every probe decoder capped at kMaxFramePixels.
  int FindStreamInfo() {
    std::vector<AVDictionary*> stream_options(format->nb_streams, nullptr);
    for (AVDictionary*& o : stream_options) av_dict_set_int(&o, "max_pixels", kMaxFramePixels, 0);
    const int r = avformat_find_stream_info(format, stream_options.data());
    for (AVDictionary*& o : stream_options) av_dict_free(&o);
    return r;
  }

  void OpenFile(const std::string& file) {
    InstallFfmpegSettings();
    int r = avformat_open_input(&format, file.c_str(), nullptr, nullptr);
    ARREG_CHECK_INPUT(r >= 0, file, "", "cannot open video: ", AvErrorString(r));
    r = FindStreamInfo();
    ARREG_CHECK_INPUT(r >= 0, file, "", "cannot read stream information: ", AvErrorString(r));
    // The stream first, its decoder second: av_find_best_stream returns an error code, not a
    // stream index, when the best stream has no decoder, so the codec could not be named.
    stream_index = av_find_best_stream(format, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
    ARREG_CHECK_INPUT(stream_index >= 0 && stream_index < static_cast<int>(format->nb_streams),
                      file, "", "no video stream");
    AVStream* stream = format->streams[stream_index];
    const AVCodec* codec = avcodec_find_decoder(stream->codecpar->codec_id);
    ARREG_CHECK_INPUT(codec != nullptr, file, "", "unsupported codec '",
                      avcodec_get_name(stream->codecpar->codec_id),
                      "' (no decoder in this FFmpeg build)");
    decoder = avcodec_alloc_context3(codec);
    ARREG_ASSERT(decoder != nullptr, "");
    r = avcodec_parameters_to_context(decoder, stream->codecpar);
    ARREG_CHECK_INPUT(r >= 0, file, "", "bad codec parameters: ", AvErrorString(r));
    decoder->thread_count = options.decode_threads;
    // A frame of another size than the first is damage (DecodeNext); one far larger than the
    // stream declares is not even decoded: a corrupt header can announce a frame of tens of
    // megapixels in a tiny stream, and decoding it costs a fraction of a second per frame. The
    // decoder refuses frames above this count (a packet it cannot decode, handled like any
    // other damage).
    const int64_t declared = int64_t{stream->codecpar->width} * stream->codecpar->height;
    ARREG_CHECK_INPUT(declared <= kMaxFramePixels, file, "", "frame size ", stream->codecpar->width,
                      "x", stream->codecpar->height,
                      " is above the supported maximum of 4096x4096 pixels");
    if (declared > 0)
      decoder->max_pixels =
          std::min(std::max(kMaxPixelsFactor * declared, kMinMaxPixels), kMaxFramePixels);
    if (options.skip_loop_filter) decoder->skip_loop_filter = AVDISCARD_ALL;
    r = avcodec_open2(decoder, codec, nullptr);
    ARREG_CHECK_INPUT(r >= 0, file, "", "cannot open decoder '", codec->name,
                      "': ", AvErrorString(r));
    packet = av_packet_alloc();
    frame = av_frame_alloc();
    ARREG_ASSERT(packet && frame, "");

    time_base = stream->time_base;
    start_pts = stream->start_time != AV_NOPTS_VALUE ? stream->start_time : 0;
    const AVRational rate = av_guess_frame_rate(format, stream, nullptr);
    fps = rate.num > 0 && rate.den > 0 ? av_q2d(rate) : 25.0;
    width = decoder->width;
    height = decoder->height;
    ARREG_CHECK_INPUT(width > 0 && height > 0, file, "",
                      "video stream has no frame size (no frame decodable up to 4096x4096 pixels)");

    frame_count = static_cast<int>(stream->nb_frames);
    if (frame_count <= 0) {
      // mkv/avi often carry no count: count the packets (demuxing only, cheap).
      frame_count = 0;
      while (av_read_frame(format, packet) >= 0) {
        if (packet->stream_index == stream_index) ++frame_count;
        av_packet_unref(packet);
      }
      r = av_seek_frame(format, stream_index, start_pts, AVSEEK_FLAG_BACKWARD);
      ARREG_CHECK_INPUT(r >= 0, file, "",
                        "cannot rewind after counting frames: ", AvErrorString(r));
      avcodec_flush_buffers(decoder);
    }
    ARREG_CHECK_INPUT(frame_count > 0, file, "", "video stream holds no frames");

    // The first frame must decode: otherwise there is nothing to process.
    const bool ok = EnsureFrame();
    ARREG_CHECK_INPUT(ok, file, FrameWhere(0),
                      "cannot decode the first frame (corrupt file or "
                      "unsupported codec '",
                      codec->name, "')");
    width = frame->width;
    height = frame->height;
    size_known = true;

    limited_to_full_lut.create(1, 256, CV_8U);
    for (int i = 0; i < 256; ++i)
      limited_to_full_lut.at<uint8_t>(i) =
          cv::saturate_cast<uint8_t>(std::lround((i - 16) * 255.0 / 219.0));
  }

  void Seek(int target) {
    ARREG_CHECK_INPUT(open, path, "", "Seek() on a reader that is not open");
    ARREG_CHECK_INPUT(target >= 0 && target < frame_count, path, FrameWhere(target),
                      "cannot seek there: the video has ", frame_count, " frames");
    if (is_sequence) {
      next_index = target;
      return;
    }
    if (frame_ready && target == next_index) return;
    const int64_t target_pts = start_pts + std::llround(target / (fps * av_q2d(time_base)));
    int r = av_seek_frame(format, stream_index, target_pts, AVSEEK_FLAG_BACKWARD);
    if (r < 0) r = av_seek_frame(format, stream_index, start_pts, AVSEEK_FLAG_BACKWARD);
    ARREG_CHECK_INPUT(r >= 0, path, FrameWhere(target), "seek failed: ", AvErrorString(r));
    avcodec_flush_buffers(decoder);
    frame_ready = false;
    flushing = false;
    finished = false;
    damaged_run_start = -1;
    // Decode from the key frame before `target` up to it. Frames are counted
    // by their timestamps, which the seek leaves consistent.
    next_index = target;
    for (;;) {
      if (!DecodeNext()) {
        throw Error(path, FrameWhere(target), "seek failed: the stream ends before this frame");
      }
      const int64_t index = FrameIndexOf(frame->best_effort_timestamp);
      ARREG_CHECK_INPUT(index >= 0, path, FrameWhere(target),
                        "cannot seek: frames carry no timestamps");
      if (index >= target) break;
    }
    next_index = target;
    frame_ready = true;
  }
};

VideoReader::VideoReader() : impl_(std::make_unique<Impl>()) {}
VideoReader::~VideoReader() = default;

void VideoReader::Open(const std::string& path, const VideoReaderOptions& options) {
  options.Check();
  impl_ = std::make_unique<Impl>();
  impl_->path = path;
  impl_->options = options;
  std::error_code ec;
  ARREG_CHECK_INPUT(fs::exists(path, ec), path, "", "file not found");
  if (fs::is_directory(path, ec)) {
    impl_->OpenSequence(path);
  } else {
    impl_->OpenFile(path);
  }
  impl_->open = true;
}

void VideoReader::Close() { impl_ = std::make_unique<Impl>(); }
bool VideoReader::is_open() const { return impl_->open; }
const std::string& VideoReader::path() const { return impl_->path; }
bool VideoReader::is_image_sequence() const { return impl_->is_sequence; }
int VideoReader::frame_count() const { return impl_->frame_count; }
double VideoReader::fps() const { return impl_->fps; }
int VideoReader::width() const { return impl_->width; }
int VideoReader::height() const { return impl_->height; }
int VideoReader::next_frame_index() const { return impl_->next_index; }
bool VideoReader::truncated() const { return impl_->truncated; }
const std::vector<int>& VideoReader::damaged_frames() const { return impl_->damaged; }

bool VideoReader::Read(cv::Mat* bgr) {
  ARREG_ASSERT(bgr != nullptr, "");
  Impl& d = *impl_;
  ARREG_CHECK_INPUT(d.open, d.path, "", "Read() on a reader that is not open");
  if (d.is_sequence) {
    if (d.next_index >= d.frame_count) return false;
    cv::Mat image = d.ReadImage(cv::IMREAD_COLOR);
    *bgr = image;
    ++d.next_index;
    return true;
  }
  if (!d.EnsureFrame()) return false;
  AVFrame* f = d.frame;
  d.sws = sws_getCachedContext(d.sws, f->width, f->height, static_cast<AVPixelFormat>(f->format),
                               f->width, f->height, AV_PIX_FMT_BGR24, SWS_BILINEAR, nullptr,
                               nullptr, nullptr);
  ARREG_CHECK_INPUT(d.sws != nullptr, d.path, FrameWhere(d.next_index),
                    "cannot convert pixel format '",
                    av_get_pix_fmt_name(static_cast<AVPixelFormat>(f->format)), "' to BGR");
  const int src_range = FullRange(*f) ? 1 : 0;
  const int* coefficients = sws_getCoefficients(SwsColorspace(*f));
  sws_setColorspaceDetails(d.sws, coefficients, src_range, sws_getCoefficients(SWS_CS_DEFAULT), 1,
                           0, 1 << 16, 1 << 16);
  bgr->create(f->height, f->width, CV_8UC3);
  uint8_t* dst[4] = {bgr->data, nullptr, nullptr, nullptr};
  int dst_stride[4] = {static_cast<int>(bgr->step[0]), 0, 0, 0};
  sws_scale(d.sws, f->data, f->linesize, 0, f->height, dst, dst_stride);
  d.frame_ready = false;
  ++d.next_index;
  return true;
}

bool VideoReader::ReadGray(cv::Mat* gray) {
  ARREG_ASSERT(gray != nullptr, "");
  Impl& d = *impl_;
  ARREG_CHECK_INPUT(d.open, d.path, "", "ReadGray() on a reader that is not open");
  if (d.is_sequence) {
    if (d.next_index >= d.frame_count) return false;
    *gray = d.ReadImage(cv::IMREAD_GRAYSCALE);
    ++d.next_index;
    return true;
  }
  if (!d.EnsureFrame()) return false;
  AVFrame* f = d.frame;
  const auto pix_fmt = static_cast<AVPixelFormat>(f->format);
  const AVPixFmtDescriptor* desc = av_pix_fmt_desc_get(pix_fmt);
  const bool luma_plane =
      desc != nullptr &&
      !(desc->flags & (AV_PIX_FMT_FLAG_RGB | AV_PIX_FMT_FLAG_PAL | AV_PIX_FMT_FLAG_BITSTREAM)) &&
      desc->comp[0].plane == 0 && desc->comp[0].depth == 8 && desc->comp[0].step == 1 &&
      desc->comp[0].offset == 0;
  if (luma_plane) {
    const cv::Mat y(f->height, f->width, CV_8UC1, f->data[0], static_cast<size_t>(f->linesize[0]));
    const bool full_range = FullRange(*f) || pix_fmt == AV_PIX_FMT_GRAY8 ||
                            pix_fmt == AV_PIX_FMT_YUVJ420P || pix_fmt == AV_PIX_FMT_YUVJ422P ||
                            pix_fmt == AV_PIX_FMT_YUVJ444P || pix_fmt == AV_PIX_FMT_YUVJ440P;
    if (full_range) {
      y.copyTo(*gray);
    } else {
      cv::LUT(y, d.limited_to_full_lut, *gray);
    }
    d.frame_ready = false;
    ++d.next_index;
    return true;
  }
  cv::Mat bgr;
  if (!Read(&bgr)) return false;
  cv::cvtColor(bgr, *gray, cv::COLOR_BGR2GRAY);
  return true;
}

void VideoReader::Seek(int frame) { impl_->Seek(frame); }

// ---------------------------------------------------------------------------
// VideoWriter

struct VideoWriter::Impl {
  std::string path, temporary;
  VideoWriterOptions options;
  int width = 0, height = 0;
  int frames = 0;
  bool open = false;
  AVFormatContext* format = nullptr;
  AVCodecContext* encoder = nullptr;
  AVStream* stream = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  SwsContext* sws = nullptr;
  cv::Mat bgr;  // converted input when it is grey

  void Release() {
    sws_freeContext(sws);
    sws = nullptr;
    av_frame_free(&frame);
    av_packet_free(&packet);
    avcodec_free_context(&encoder);
    if (format) {
      if (format->pb && !(format->oformat->flags & AVFMT_NOFILE)) avio_closep(&format->pb);
      avformat_free_context(format);
      format = nullptr;
    }
    stream = nullptr;
  }

  void Abandon() {
    Release();
    if (!temporary.empty()) {
      std::error_code ec;
      fs::remove(temporary, ec);
      temporary.clear();
    }
    open = false;
  }

  ~Impl() { Abandon(); }

  // Sends `f` (nullptr: flush) and writes the packets that come out.
  void Encode(AVFrame* f) {
    int r = avcodec_send_frame(encoder, f);
    ARREG_CHECK_INPUT(r >= 0, path, FrameWhere(frames),
                      "encoder rejected the frame: ", AvErrorString(r));
    for (;;) {
      r = avcodec_receive_packet(encoder, packet);
      if (r == AVERROR(EAGAIN) || r == AVERROR_EOF) return;
      ARREG_CHECK_INPUT(r >= 0, path, FrameWhere(frames), "encoding failed: ", AvErrorString(r));
      av_packet_rescale_ts(packet, encoder->time_base, stream->time_base);
      packet->stream_index = stream->index;
      r = av_interleaved_write_frame(format, packet);
      av_packet_unref(packet);
      ARREG_CHECK_INPUT(r >= 0, path, FrameWhere(frames),
                        "cannot write to the file: ", AvErrorString(r));
    }
  }
};

VideoWriter::VideoWriter() : impl_(std::make_unique<Impl>()) {}
VideoWriter::~VideoWriter() = default;
bool VideoWriter::is_open() const { return impl_->open; }
int VideoWriter::frames_written() const { return impl_->frames; }

void VideoWriter::Open(const std::string& path, int width, int height, double fps,
                       const VideoWriterOptions& options) {
  options.Check();
  ARREG_CHECK_INPUT(width > 0 && height > 0, path, "", "frame size must be positive, got ", width,
                    "x", height);
  ARREG_CHECK_INPUT(fps > 0 && std::isfinite(fps), path, "", "fps must be > 0, got ", fps);
  const AVPixelFormat pix_fmt = av_get_pix_fmt(options.pixel_format.c_str());
  const AVPixFmtDescriptor* desc = av_pix_fmt_desc_get(pix_fmt);
  const int align_x = 1 << desc->log2_chroma_w, align_y = 1 << desc->log2_chroma_h;
  ARREG_CHECK_INPUT(width % align_x == 0 && height % align_y == 0, path, "", "frame size ", width,
                    "x", height, " must be a multiple of ", align_x, "x", align_y, " for ",
                    options.pixel_format);
  InstallFfmpegSettings();
  impl_ = std::make_unique<Impl>();
  Impl& d = *impl_;
  d.path = path;
  d.options = options;
  d.width = width;
  d.height = height;
  d.temporary = TemporaryPathFor(path);
  try {
    int r = avformat_alloc_output_context2(&d.format, nullptr, nullptr, d.temporary.c_str());
    ARREG_CHECK_INPUT(
        r >= 0 && d.format, path, "",
        "unknown container for this extension (use .mp4, .mkv or .avi): ", AvErrorString(r));
    const AVCodec* codec = avcodec_find_encoder_by_name(options.codec.c_str());
    ARREG_CHECK_INPUT(codec != nullptr, path, "", "encoder '", options.codec,
                      "' is not available in this FFmpeg build");
    d.stream = avformat_new_stream(d.format, nullptr);
    d.encoder = avcodec_alloc_context3(codec);
    ARREG_ASSERT(d.stream && d.encoder, "");
    const AVRational rate = av_d2q(fps, 100000);
    d.encoder->width = width;
    d.encoder->height = height;
    d.encoder->pix_fmt = pix_fmt;
    d.encoder->time_base = av_inv_q(rate);
    d.encoder->framerate = rate;
    d.encoder->thread_count = options.encode_threads;
    if (d.format->oformat->flags & AVFMT_GLOBALHEADER)
      d.encoder->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
    if (d.encoder->priv_data) {
      // crf/preset exist for x264/x265; other encoders keep their defaults.
      if (av_opt_find(d.encoder->priv_data, "crf", nullptr, 0, 0))
        av_opt_set_double(d.encoder->priv_data, "crf", options.crf, 0);
      if (!options.preset.empty() && av_opt_find(d.encoder->priv_data, "preset", nullptr, 0, 0)) {
        r = av_opt_set(d.encoder->priv_data, "preset", options.preset.c_str(), 0);
        ARREG_CHECK_INPUT(r >= 0, "", "VideoWriterOptions.preset", "encoder '", options.codec,
                          "' rejects preset '", options.preset, "'");
      }
      if (!options.tune.empty() && av_opt_find(d.encoder->priv_data, "tune", nullptr, 0, 0)) {
        r = av_opt_set(d.encoder->priv_data, "tune", options.tune.c_str(), 0);
        ARREG_CHECK_INPUT(r >= 0, "", "VideoWriterOptions.tune", "encoder '", options.codec,
                          "' rejects tune '", options.tune, "'");
      }
    }
    r = avcodec_open2(d.encoder, codec, nullptr);
    // x264 checks its preset and tune only here.
    ARREG_CHECK_INPUT(r >= 0, path, "", "cannot open encoder '", options.codec, "' for ", width,
                      "x", height, " ", options.pixel_format, " (preset '", options.preset,
                      "', tune '", options.tune, "'): ", AvErrorString(r));
    r = avcodec_parameters_from_context(d.stream->codecpar, d.encoder);
    ARREG_ASSERT(r >= 0, "");
    d.stream->time_base = d.encoder->time_base;
    d.stream->avg_frame_rate = rate;
    if (!(d.format->oformat->flags & AVFMT_NOFILE)) {
      r = avio_open(&d.format->pb, d.temporary.c_str(), AVIO_FLAG_WRITE);
      ARREG_CHECK_INPUT(r >= 0, path, "", "cannot create the file: ", AvErrorString(r));
    }
    AVDictionary* mux_options = nullptr;
    if (options.faststart) av_dict_set(&mux_options, "movflags", "+faststart", 0);
    r = avformat_write_header(d.format, &mux_options);
    av_dict_free(&mux_options);
    ARREG_CHECK_INPUT(r >= 0, path, "", "cannot write the container header: ", AvErrorString(r));

    d.frame = av_frame_alloc();
    d.packet = av_packet_alloc();
    ARREG_ASSERT(d.frame && d.packet, "");
    d.frame->format = pix_fmt;
    d.frame->width = width;
    d.frame->height = height;
    r = av_frame_get_buffer(d.frame, 0);
    ARREG_ASSERT(r >= 0, AvErrorString(r), "");
    d.sws = sws_getContext(width, height, AV_PIX_FMT_BGR24, width, height, pix_fmt, SWS_BILINEAR,
                           nullptr, nullptr, nullptr);
    ARREG_CHECK_INPUT(d.sws != nullptr, path, "", "cannot convert BGR to ", options.pixel_format);
  } catch (...) {
    d.Abandon();
    throw;
  }
  d.open = true;
}

void VideoWriter::Write(const cv::Mat& image) {
  Impl& d = *impl_;
  ARREG_CHECK_INPUT(d.open, d.path, "", "Write() on a writer that is not open");
  ARREG_CHECK_INPUT(image.type() == CV_8UC3 || image.type() == CV_8UC1, d.path,
                    FrameWhere(d.frames), "expected an 8-bit BGR or grey image");
  ARREG_CHECK_INPUT(image.cols == d.width && image.rows == d.height, d.path, FrameWhere(d.frames),
                    "image is ", image.cols, "x", image.rows, " but the video is ", d.width, "x",
                    d.height);
  const cv::Mat* bgr = &image;
  if (image.type() == CV_8UC1) {
    cv::cvtColor(image, d.bgr, cv::COLOR_GRAY2BGR);
    bgr = &d.bgr;
  }
  int r = av_frame_make_writable(d.frame);
  ARREG_ASSERT(r >= 0, AvErrorString(r), "");
  const uint8_t* src[4] = {bgr->data, nullptr, nullptr, nullptr};
  const int src_stride[4] = {static_cast<int>(bgr->step[0]), 0, 0, 0};
  sws_scale(d.sws, src, src_stride, 0, d.height, d.frame->data, d.frame->linesize);
  d.frame->pts = d.frames;
  d.Encode(d.frame);
  ++d.frames;
}

void VideoWriter::Close() {
  Impl& d = *impl_;
  if (!d.open) return;
  try {
    d.Encode(nullptr);
    const int r = av_write_trailer(d.format);
    ARREG_CHECK_INPUT(r >= 0, d.path, "", "cannot finish the container: ", AvErrorString(r));
    if (d.format->pb && !(d.format->oformat->flags & AVFMT_NOFILE)) {
      avio_closep(&d.format->pb);
    }
    d.Release();
    CommitTemporaryFile(d.temporary, d.path);
    d.temporary.clear();
    d.open = false;
  } catch (...) {
    d.Abandon();
    throw;
  }
}

}  // namespace arreg
