#include "cutting/tet_cut_operation.h"

#include <algorithm>
#include <functional>
#include <numeric>
#include <unordered_map>

namespace arreg::cutting::cut_internal {

void CutOperation::Separate() {
  // Unsew faces whose three vertices are marked (on S).
  std::vector<int> marked_list;
  for (int v = 0; v < static_cast<int>(marked_.size()); ++v)
    if (marked_[v]) marked_list.push_back(v);
  auto all_marked = [&](const Tet& t) {
    return Marked(t[0]) && Marked(t[1]) && Marked(t[2]) && Marked(t[3]);
  };
  for (int v : marked_list)
    for (int t : m_.vertex_tets_[v]) {
      const Tet& q = m_.tets_[t];
      if (all_marked(q)) continue;
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        if (std::min({a, b, c}) != v || !Marked(a) || !Marked(b) || !Marked(c)) continue;
        const std::uint64_t key = FaceKey(a, b, c);
        if (m_.unsewn_.count(key)) continue;
        int other = -1;
        for (int t2 : m_.vertex_tets_[a])
          if (t2 != t && Contains(m_.tets_[t2], b) && Contains(m_.tets_[t2], c)) other = t2;
        if (other < 0 || all_marked(m_.tets_[other])) continue;
        m_.unsewn_.insert(key);
        separated_faces_.push_back({a, b, c});
      }
    }
  // Pieces of split unsewn faces.
  for (const auto& [y, pts] : unsewn_splits_)
    for (int t : m_.vertex_tets_[y]) {
      const Tet& q = m_.tets_[t];
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        int in = 0;
        bool has_y = false;
        for (int x : {a, b, c}) {
          if (x == y)
            has_y = true;
          else if (std::find(pts.begin(), pts.end(), x) != pts.end())
            ++in;
        }
        if (has_y && in == 2) m_.unsewn_.insert(FaceKey(a, b, c));
      }
    }
  // Duplicate vertices whose elements fall apart into several groups across unsewn faces.
  std::vector<int> candidates;
  for (std::uint64_t key : m_.unsewn_) {
    candidates.push_back(static_cast<int>(key >> 42));
    candidates.push_back(static_cast<int>((key >> 21) & 0x1fffff));
    candidates.push_back(static_cast<int>(key & 0x1fffff));
  }
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  for (int v : candidates) {
    const std::vector<int> around = m_.vertex_tets_[v];
    const int n = static_cast<int>(around.size());
    std::vector<int> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    std::function<int(int)> find = [&](int i) {
      return parent[i] == i ? i : parent[i] = find(parent[i]);
    };
    std::unordered_map<std::uint64_t, int> first;
    for (int i = 0; i < n; ++i) {
      const Tet& q = m_.tets_[around[i]];
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        if (a != v && b != v && c != v) continue;
        const std::uint64_t key = FaceKey(a, b, c);
        auto it = first.find(key);
        if (it == first.end()) {
          first.emplace(key, i);
        } else if (!m_.unsewn_.count(key)) {
          parent[find(i)] = find(it->second);
        }
      }
    }
    std::vector<int> roots;
    for (int i = 0; i < n; ++i)
      if (find(i) == i) roots.push_back(i);
    if (roots.size() < 2) continue;
    const STriangle* nearest = nullptr;
    DistanceToSurface(m_.current_[v], &nearest);
    // The group holding the lowest element index keeps the vertex.
    for (size_t g = 1; g < roots.size(); ++g) {
      const int root = find(roots[g]);
      const int copy = static_cast<int>(m_.rest_.size());
      m_.rest_.push_back(m_.rest_[v]);
      m_.current_.push_back(m_.current_[v]);
      m_.velocity_.push_back(m_.velocity_[v]);
      m_.vertex_tets_.emplace_back();
      marked_.push_back(marked_[v]);
      Vec3 centroid = Vec3::Zero();
      int count = 0;
      for (int i = 0; i < n; ++i) {
        if (find(i) != root) continue;
        const int t = around[i];
        Tet& q = m_.tets_[t];
        for (int k = 0; k < 4; ++k) {
          centroid += m_.current_[q[k]];
          if (q[k] == v) q[k] = copy;
        }
        ++count;
        m_.vertex_tets_[copy].push_back(t);
        auto& list = m_.vertex_tets_[v];
        list.erase(std::find(list.begin(), list.end(), t));
        changed_slots_.push_back(t);
      }
      centroid /= 4.0 * count;
      DuplicatedVertex d;
      d.index = copy;
      d.original = v;
      d.side = (nearest && nearest->normal.dot(centroid - m_.current_[v]) < 0) ? -1 : 1;
      duplicated_.push_back(d);
    }
  }
  summary_.num_duplicated_vertices = static_cast<int>(duplicated_.size());
  // Faces that are now true boundary no longer need to be remembered.
  for (auto it = m_.unsewn_.begin(); it != m_.unsewn_.end();) {
    const int a = static_cast<int>(*it >> 42), b = static_cast<int>((*it >> 21) & 0x1fffff),
              c = static_cast<int>(*it & 0x1fffff);
    int count = 0;
    for (int t : m_.vertex_tets_[a])
      if (Contains(m_.tets_[t], b) && Contains(m_.tets_[t], c)) ++count;
    if (count < 2)
      it = m_.unsewn_.erase(it);
    else
      ++it;
  }
}

}  // namespace arreg::cutting::cut_internal
