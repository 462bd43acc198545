#include "exocet_mosaic/ros/frame_assembler.h"

#include <stdexcept>

namespace exocet_mosaic {

FrameAssembler::FrameAssembler(double timeout_s, std::size_t max_pending)
    : timeout_s_(timeout_s), max_pending_(max_pending) {
  if (!(timeout_s > 0.0)) throw std::invalid_argument("frame assembler: timeout_s must be > 0");
  if (max_pending < 1) throw std::invalid_argument("frame assembler: max_pending must be >= 1");
}

AssembledFrame* FrameAssembler::slot(std::int64_t stamp_ns, double now_s) {
  if (last_released_ns_ && stamp_ns <= *last_released_ns_) {
    ++late_parts_;
    return nullptr;
  }
  AssembledFrame& frame = frames_[stamp_ns];
  frame.stamp_ns = stamp_ns;
  if (!frame.decode_image) frame.image_arrival_s = now_s;
  return &frame;
}

bool FrameAssembler::addImage(std::int64_t stamp_ns, ImageDecoder decode_image, double now_s,
                              cv::Size image_size, int image_channels) {
  AssembledFrame* frame = slot(stamp_ns, now_s);
  if (!frame) return false;
  if (frame->decode_image) {
    ++duplicate_images_;
    return false;
  }
  frame->decode_image = std::move(decode_image);
  frame->image_size = image_size;
  frame->image_channels = image_channels;
  frame->image_arrival_s = now_s;
  return true;
}

bool FrameAssembler::addMotion(std::int64_t stamp_ns, const MotionPart& motion, double now_s) {
  AssembledFrame* frame = slot(stamp_ns, now_s);
  if (!frame) return false;
  frame->motion = motion;
  return true;
}

bool FrameAssembler::addPose(std::int64_t stamp_ns, const PosePart& pose, double now_s) {
  AssembledFrame* frame = slot(stamp_ns, now_s);
  if (!frame) return false;
  frame->pose = pose;
  return true;
}

bool FrameAssembler::addHeight(std::int64_t stamp_ns, double camera_height_m, double now_s) {
  AssembledFrame* frame = slot(stamp_ns, now_s);
  if (!frame) return false;
  frame->camera_height_m = camera_height_m;
  return true;
}

void FrameAssembler::release(std::map<std::int64_t, AssembledFrame>::iterator end, std::vector<AssembledFrame>* out) {
  for (auto it = frames_.begin(); it != end;) {
    if (it->second.decode_image) out->push_back(std::move(it->second));
    last_released_ns_ = it->first;
    it = frames_.erase(it);
  }
}

std::vector<AssembledFrame> FrameAssembler::popReady(double now_s) {
  std::vector<AssembledFrame> out;
  // The newest complete frame releases every older one: their missing parts will not come any more (the chain of
  // nodes keeps the stamp order).
  auto newest_complete = frames_.end();
  for (auto it = frames_.begin(); it != frames_.end(); ++it)
    if (it->second.complete()) newest_complete = it;
  if (newest_complete != frames_.end()) release(std::next(newest_complete), &out);
  // Then the ones that waited too long or overflow the buffer, oldest first.
  while (!frames_.empty()) {
    const AssembledFrame& oldest = frames_.begin()->second;
    const bool has_image = static_cast<bool>(oldest.decode_image);
    const bool stale = now_s - oldest.image_arrival_s > timeout_s_;
    if (!(stale || pendingImages() > max_pending_)) break;
    if (has_image) ++timed_out_;
    release(std::next(frames_.begin()), &out);
  }
  return out;
}

std::vector<AssembledFrame> FrameAssembler::popAll() {
  std::vector<AssembledFrame> out;
  release(frames_.end(), &out);
  return out;
}

void FrameAssembler::reset() {
  frames_.clear();
  last_released_ns_.reset();
}

std::size_t FrameAssembler::pendingImages() const {
  std::size_t n = 0;
  for (const auto& [stamp, frame] : frames_)
    if (frame.decode_image) ++n;
  return n;
}

}  // namespace exocet_mosaic
