#pragma once
// The map structure shared by every EKF of a bank (docs/sog.md §8): all filters hold the
// same features at the same state offsets, so bookkeeping (ids, kinds, offsets, match
// statistics) lives here once and restructuring is planned once for all filters.
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "rscalib/sog/state_layout.hpp"

namespace rscalib::sog {

struct MapFeature {
  int64_t id = 0;
  FeatureKind kind = FeatureKind::kInverseDepth;
  int offset = 0;           // first state index
  int times_predicted = 0;  // searched for (predicted visible)
  int times_matched = 0;    // found and used in an update
  int64_t frame_added = 0;
  int64_t frame_last_matched = -1;  // bank frame of the last use in an update (-1: never)
};

// What a restructuring does to every filter's state: features converted from inverse depth
// to XYZ (in place, first 3 of their 6 entries), then only the state indices in `keep` stay.
struct StateRestructure {
  std::vector<int> converted_offsets;  // offsets (before) of features converted to XYZ
  std::vector<int> keep;               // indices (before, after conversion) kept, in order
  int new_dim = 0;
  bool trivial = true;  // nothing removed or converted
};

class FeatureMap {
 public:
  int state_dim() const { return state_dim_; }
  int size() const { return static_cast<int>(features_.size()); }
  const MapFeature& operator[](int index) const { return features_[index]; }
  MapFeature& operator[](int index) { return features_[index]; }
  const std::vector<MapFeature>& features() const { return features_; }
  // Index of a feature id, -1 if unknown.
  int IndexOf(int64_t id) const {
    const auto it = index_.find(id);
    return it == index_.end() ? -1 : it->second;
  }

  // Appends inverse-depth features; returns their ids.
  std::vector<int64_t> AddInverseDepth(int count, int64_t frame) {
    std::vector<int64_t> ids;
    for (int i = 0; i < count; ++i) {
      MapFeature f;
      f.id = next_id_++;
      f.offset = state_dim_;
      f.frame_added = frame;
      state_dim_ += kInverseDepthDim;
      index_[f.id] = static_cast<int>(features_.size());
      features_.push_back(f);
      ids.push_back(f.id);
    }
    return ids;
  }

  // Plans removing the features flagged in `remove` and converting those flagged in `convert`
  // (both indexed like features()); Apply() then updates the bookkeeping.
  StateRestructure Plan(const std::vector<bool>& remove, const std::vector<bool>& convert) const {
    StateRestructure plan;
    for (int i = 0; i < kCameraDim; ++i) plan.keep.push_back(i);
    for (int k = 0; k < size(); ++k) {
      const MapFeature& f = features_[k];
      if (remove[k]) {
        plan.trivial = false;
        continue;
      }
      int dim = FeatureDim(f.kind);
      if (convert[k] && f.kind == FeatureKind::kInverseDepth) {
        plan.converted_offsets.push_back(f.offset);
        plan.trivial = false;
        dim = kXyzDim;
      }
      for (int i = 0; i < dim; ++i) plan.keep.push_back(f.offset + i);
    }
    plan.new_dim = static_cast<int>(plan.keep.size());
    return plan;
  }

  void Apply(const std::vector<bool>& remove, const std::vector<bool>& convert) {
    std::vector<MapFeature> kept;
    int offset = kCameraDim;
    index_.clear();
    for (int k = 0; k < size(); ++k) {
      if (remove[k]) continue;
      MapFeature f = features_[k];
      if (convert[k]) f.kind = FeatureKind::kXyz;
      f.offset = offset;
      offset += FeatureDim(f.kind);
      index_[f.id] = static_cast<int>(kept.size());
      kept.push_back(f);
    }
    features_.swap(kept);
    state_dim_ = offset;
  }

 private:
  std::vector<MapFeature> features_;
  std::unordered_map<int64_t, int> index_;
  int state_dim_ = kCameraDim;
  int64_t next_id_ = 0;
};

}  // namespace rscalib::sog
