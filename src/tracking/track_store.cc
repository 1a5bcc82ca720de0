// TrackStore: every feature ever detected, its SURF keypoint, descriptor and history.
#include "tracking/tracker.h"

#include <ostream>

#include "core/error.h"
#include "core/file_util.h"

namespace arreg {

int TrackStore::Add(const SurfKeypoint& keypoint, const cv::Mat& descriptor_row) {
  ARREG_ASSERT(descriptor_row.rows == 1 && descriptor_row.cols == kSurfDescriptorSize &&
                   descriptor_row.type() == CV_32F,
               "");
  const int id = num_features();
  histories_.emplace_back();
  keypoints_.push_back(keypoint);
  descriptors_.push_back(descriptor_row);
  return id;
}

void TrackStore::Record(int id, const TrackObservation& observation) {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  histories_[id].push_back(observation);
}

const std::vector<TrackObservation>& TrackStore::history(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return histories_[id];
}

const SurfKeypoint& TrackStore::keypoint(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return keypoints_[id];
}

cv::Mat TrackStore::descriptor(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return descriptors_.row(id);
}

void TrackStore::WriteCsv(const std::string& path) const {
  WriteFileAtomic(path, [this](std::ostream& out) {
    out << "id,frame,x_px,y_px,status\n";
    for (int id = 0; id < num_features(); ++id)
      for (const TrackObservation& o : histories_[id])
        out << id << ',' << o.frame << ',' << o.position_px.x << ',' << o.position_px.y << ','
            << TrackStatusName(o.status) << '\n';
  });
}

}  // namespace arreg
