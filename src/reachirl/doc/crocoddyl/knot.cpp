// The knot of reachirl's Crocoddyl shooting problem, compiled: the same action model as knots.py's KnotModel
// (augmented state x = (q, q̇, τ_prev), control u = τ; the inner IntegratedActionModelEuler on (q, q̇) carries the
// built-in costs and the constraints; energy and torque change are added here), without Python in CSQP's loop.
// Built and loaded by reachirl.doc.crocoddyl.native; every line of arithmetic follows knots.py's, in its order.

#include <boost/python.hpp>
#include <cmath>
#include <crocoddyl/core/action-base.hpp>
#include <crocoddyl/core/states/euclidean.hpp>
#include <memory>
#include <stdexcept>

namespace bp = boost::python;
using crocoddyl::ActionDataAbstract;
using crocoddyl::ActionModelAbstract;
using Eigen::VectorXd;
typedef Eigen::Ref<const VectorXd> ConstRef;

namespace {

const std::size_t NX = 6, NU = 2;

class Knot;

struct KnotData : public ActionDataAbstract {
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW
  explicit KnotData(Knot* model);
  std::shared_ptr<ActionDataAbstract> inner;
};

class Knot : public ActionModelAbstract {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  Knot(std::shared_ptr<ActionModelAbstract> inner, std::size_t ng, bool terminal, double eps)
      : ActionModelAbstract(std::make_shared<crocoddyl::StateVector>(NX), NU, 1, ng, 0),
        inner_(inner),
        terminal_(terminal),
        eps_(eps) {}

  void calc(const std::shared_ptr<ActionDataAbstract>& data, const ConstRef& x, const ConstRef& u) override {
    if (terminal_) {
      calc(data, x);
      return;
    }
    KnotData* d = static_cast<KnotData*>(data.get());
    inner_->calc(d->inner, x.head<4>(), u);
    double cost = d->inner->cost;
    if (w_energy > 0.0 || w_torque_change > 0.0) {
      const double v0 = x[2], v1 = x[3], p0 = x[4], p1 = x[5], u0 = u[0], u1 = u[1];
      if (w_energy > 0.0) {
        const double r = v0 * u0 + v1 * u1;
        cost += w_energy * dt_ * (std::sqrt(r * r + eps_ * eps_) - eps_);
      }
      if (w_torque_change > 0.0) {
        const double d0 = u0 - p0, d1 = u1 - p1;
        cost += w_torque_change / dt_ * (d0 * d0 + d1 * d1);
      }
    }
    d->cost = cost;
    d->xnext.head<4>() = d->inner->xnext;
    d->xnext.tail<2>() = u;
    if (ng_) d->g = d->inner->g;
  }

  void calc(const std::shared_ptr<ActionDataAbstract>& data, const ConstRef& x) override {
    KnotData* d = static_cast<KnotData*>(data.get());
    inner_->calc(d->inner, x.head<4>());
    d->cost = d->inner->cost;
    d->xnext = x;
    if (ng_) d->g = d->inner->g;
  }

  void calcDiff(const std::shared_ptr<ActionDataAbstract>& data, const ConstRef& x, const ConstRef& u) override {
    if (terminal_) {
      calcDiff(data, x);
      return;
    }
    KnotData* d = static_cast<KnotData*>(data.get());
    const ActionDataAbstract& di = *d->inner;
    inner_->calcDiff(d->inner, x.head<4>(), u);
    d->Fx.topLeftCorner<4, 4>() = di.Fx;
    d->Fu.topRows<4>() = di.Fu;
    d->Lx.head<4>() = di.Lx;
    d->Lu = di.Lu;
    d->Lxx.topLeftCorner<4, 4>() = di.Lxx;
    d->Lxu.topRows<4>() = di.Lxu;
    d->Luu = di.Luu;
    if (ng_) {
      d->Gx.leftCols<4>() = di.Gx;
      d->Gu = di.Gu;
    }
    VectorXd& Lx = d->Lx;
    VectorXd& Lu = d->Lu;
    Eigen::MatrixXd& Lxx = d->Lxx;
    Eigen::MatrixXd& Lxu = d->Lxu;
    Eigen::MatrixXd& Luu = d->Luu;
    const double v0 = x[2], v1 = x[3], p0 = x[4], p1 = x[5], u0 = u[0], u1 = u[1];
    if (w_energy > 0.0) {
      const double r = v0 * u0 + v1 * u1;
      const double s = std::sqrt(r * r + eps_ * eps_);
      const double c = w_energy * dt_;
      const double d1 = c * r / s;
      const double d2 = c * eps_ * eps_ / (s * s * s);
      Lx[2] += d1 * u0;
      Lx[3] += d1 * u1;
      Lu[0] += d1 * v0;
      Lu[1] += d1 * v1;
      double a = d2 * u0 * u0, b = d2 * u0 * u1, e = d2 * u1 * u1;
      Lxx(2, 2) += a;
      Lxx(2, 3) += b;
      Lxx(3, 2) += b;
      Lxx(3, 3) += e;
      const double h = exact_hessian ? d1 : 0.0;
      Lxu(2, 0) += d2 * u0 * v0 + h;
      Lxu(2, 1) += d2 * u0 * v1;
      Lxu(3, 0) += d2 * u1 * v0;
      Lxu(3, 1) += d2 * u1 * v1 + h;
      a = d2 * v0 * v0, b = d2 * v0 * v1, e = d2 * v1 * v1;
      Luu(0, 0) += a;
      Luu(0, 1) += b;
      Luu(1, 0) += b;
      Luu(1, 1) += e;
    }
    const double c = 2.0 * w_torque_change / dt_;
    const double d0 = c * (u0 - p0), d1 = c * (u1 - p1);
    Lx[4] = -d0;
    Lx[5] = -d1;
    Lxx(4, 4) = Lxx(5, 5) = c;
    Lxu(4, 0) = Lxu(5, 1) = -c;
    if (c > 0.0) {
      Lu[0] += d0;
      Lu[1] += d1;
      Luu(0, 0) += c;
      Luu(1, 1) += c;
    }
  }

  void calcDiff(const std::shared_ptr<ActionDataAbstract>& data, const ConstRef& x) override {
    KnotData* d = static_cast<KnotData*>(data.get());
    const ActionDataAbstract& di = *d->inner;
    inner_->calcDiff(d->inner, x.head<4>());
    d->Lx.head<4>() = di.Lx;
    d->Lxx.topLeftCorner<4, 4>() = di.Lxx;
    if (ng_) d->Gx.leftCols<4>() = di.Gx;
  }

  std::shared_ptr<ActionDataAbstract> createData() override {
    return std::allocate_shared<KnotData>(Eigen::aligned_allocator<KnotData>(), this);
  }

  bool checkData(const std::shared_ptr<ActionDataAbstract>& data) override {
    return dynamic_cast<KnotData*>(data.get()) != nullptr;
  }

  std::shared_ptr<crocoddyl::ActionModelBase> cloneAsDouble() const override {
    return std::make_shared<Knot>(*this);
  }
  std::shared_ptr<crocoddyl::ActionModelBase> cloneAsFloat() const override {
    throw std::logic_error("reachirl's knot is double precision only");
  }

  double get_dt() const { return dt_; }
  void set_dt(double dt) { dt_ = dt; }
  bool is_terminal() const { return terminal_; }
  std::shared_ptr<ActionModelAbstract> get_inner() const { return inner_; }

  double w_energy = 0.0;
  double w_torque_change = 0.0;
  bool exact_hessian = false;

 private:
  std::shared_ptr<ActionModelAbstract> inner_;
  bool terminal_;
  double eps_;
  double dt_ = 0.0;
};

KnotData::KnotData(Knot* model) : ActionDataAbstract(model), inner(model->get_inner()->createData()) {
  Fu.bottomRows<2>().setIdentity();  // τ_prev at the next knot is this knot's τ
}

// Python's entry points (Crocoddyl's own are bound to its Python-overridable wrapper class, not to this one)
void calc3(Knot& m, const std::shared_ptr<ActionDataAbstract>& d, const VectorXd& x, const VectorXd& u) {
  m.calc(d, x, u);
}
void calc2(Knot& m, const std::shared_ptr<ActionDataAbstract>& d, const VectorXd& x) { m.calc(d, x); }
void calcDiff3(Knot& m, const std::shared_ptr<ActionDataAbstract>& d, const VectorXd& x, const VectorXd& u) {
  m.calcDiff(d, x, u);
}
void calcDiff2(Knot& m, const std::shared_ptr<ActionDataAbstract>& d, const VectorXd& x) { m.calcDiff(d, x); }
VectorXd get_g_lb(const Knot& m) { return m.get_g_lb(); }
VectorXd get_g_ub(const Knot& m) { return m.get_g_ub(); }
void set_g_lb(Knot& m, const VectorXd& v) { m.set_g_lb(v); }
void set_g_ub(Knot& m, const VectorXd& v) { m.set_g_ub(v); }

}  // namespace

BOOST_PYTHON_MODULE(_knot) {
  bp::import("crocoddyl");
  bp::class_<Knot, bp::bases<ActionModelAbstract>, std::shared_ptr<Knot>, boost::noncopyable>(
      "Knot", bp::init<std::shared_ptr<ActionModelAbstract>, std::size_t, bool, double>(
                  bp::args("self", "inner", "ng", "terminal", "energy_smoothing")))
      .def("calc", &calc3, bp::args("self", "data", "x", "u"))
      .def("calc", &calc2, bp::args("self", "data", "x"))
      .def("calcDiff", &calcDiff3, bp::args("self", "data", "x", "u"))
      .def("calcDiff", &calcDiff2, bp::args("self", "data", "x"))
      .def("createData", &Knot::createData, bp::args("self"))
      .add_property("g_lb", &get_g_lb, &set_g_lb)
      .add_property("g_ub", &get_g_ub, &set_g_ub)
      .add_property("dt", &Knot::get_dt, &Knot::set_dt)
      .add_property("terminal", &Knot::is_terminal)
      .def_readwrite("w_energy", &Knot::w_energy)
      .def_readwrite("w_torque_change", &Knot::w_torque_change)
      .def_readwrite("exact_hessian", &Knot::exact_hessian);
  bp::class_<KnotData, bp::bases<ActionDataAbstract>, std::shared_ptr<KnotData>, boost::noncopyable>("KnotData",
                                                                                                   bp::no_init)
      .add_property("inner", bp::make_getter(&KnotData::inner, bp::return_value_policy<bp::return_by_value>()));
}
