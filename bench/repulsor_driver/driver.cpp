// Benchmark driver for Henrik Schumacher's Repulsor (header-only, C++20), used by
// bench/repulsor_compare.py. It only calls Repulsor's public API, the way Repulsor's own
// Example/main.cpp and Example2/main.cpp do.
//
//     driver CURVE MODE THREADS [--theta THETA]
//
// CURVE   raw little-endian float64 array of shape (N, 3): the vertices of a closed polygon,
//         edge i = (i, (i+1) mod N).
// MODE    eg     mesh (cluster tree + block cluster tree) + TangentPointEnergy0(q=2, p=4)
//                energy and differential, timed with std::chrono::steady_clock;
//         iter   one iteration as in Repulsor's examples: mesh, energy and differential,
//                TangentPointMetric0 GMRES solve for the gradient (<= 100 iterations, relative
//                tolerance 1e-5, the metric's own preconditioner), MaximumSafeStepSize along
//                minus the gradient in [0, 1], SemiStaticUpdate, energy of the moved curve;
//         error  tree energy/differential against TangentPointEnergy_AllPairs.
// THREADS thread_count of the mesh and of its cluster tree.
// THETA   block_cluster_tree_settings.far_field_separation_parameter (default 0.5).
//
// Output: one "repulsor MODE key=value ..." line, one "repulsor memory ..." line (VmHWM);
// anything else starts with "repulsor info ".

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

// The pinned Tools (dfa339a) no longer has ToStringFPGeneral, which Repulsor's
// TangentPointEnergy_AllPairs (and others) call when they build their class name. Stand-in,
// used only for class names (these names also key Repulsor's caches, so keep q and p
// distinguishable). Declared before Repulsor's headers so that the (dependent) unqualified
// call finds it.
namespace Repulsor
{
    template<typename T>
    std::string ToStringFPGeneral( const T & x )
    {
        char buf[64];
        std::snprintf( buf, sizeof(buf), "%.17g", static_cast<double>(x) );
        return std::string(buf);
    }
}

// OpenBLAS + LAPACK(E) headers, as in Repulsor's examples on non-Apple systems.
#include "submodules/Tensors/OpenBLAS.hpp"
#include "Repulsor.hpp"

using namespace Tools;

using Int  = int;
using LInt = std::size_t;
using Real = double;

using Mesh_T   = Repulsor::SimplicialMeshBase<Real,Int,LInt>;
using Energy_T = Repulsor::EnergyBase<Mesh_T>;
using Metric_T = Repulsor::MetricBase<Mesh_T>;

using Clock = std::chrono::steady_clock;

static double seconds_since( const Clock::time_point t0 )
{
    return std::chrono::duration<double>( Clock::now() - t0 ).count();
}

static double peak_rss_mb()
{
    std::ifstream f ( "/proc/self/status" );
    std::string line;
    while( std::getline( f, line ) )
    {
        if( line.rfind( "VmHWM:", 0 ) == 0 )
        {
            return std::strtod( line.c_str() + 6, nullptr ) / 1024.0; // kB -> MB
        }
    }
    return -1.0;
}

static double norm2( const Real * a, const std::size_t n )
{
    long double s = 0;
    for( std::size_t i = 0; i < n; ++i ) { s += static_cast<long double>(a[i]) * a[i]; }
    return static_cast<double>( std::sqrt(s) );
}

static double diff_norm2( const Real * a, const Real * b, const std::size_t n )
{
    long double s = 0;
    for( std::size_t i = 0; i < n; ++i )
    {
        const long double d = static_cast<long double>(a[i]) - b[i];
        s += d * d;
    }
    return static_cast<double>( std::sqrt(s) );
}

static int usage()
{
    std::fprintf( stderr, "usage: driver CURVE (eg|iter|error) THREADS [--theta THETA] [--repeat K]\n" );
    return 2;
}

int main( int argc, char ** argv )
{
    if( argc < 4 ) { return usage(); }

    const std::string curve_file = argv[1];
    const std::string mode       = argv[2];
    const int thread_count       = std::atoi( argv[3] );
    double theta = 0.5;
    int repeat = 1;

    for( int i = 4; i < argc; ++i )
    {
        if( (std::strcmp( argv[i], "--theta" ) == 0) && (i + 1 < argc) )
        {
            theta = std::strtod( argv[++i], nullptr );
        }
        else if( (std::strcmp( argv[i], "--repeat" ) == 0) && (i + 1 < argc) )
        {
            repeat = std::atoi( argv[++i] );
        }
        else
        {
            return usage();
        }
    }

    if( (mode != "eg") && (mode != "iter") && (mode != "error") ) { return usage(); }
    if( (thread_count < 1) || (repeat < 1) ) { return usage(); }

    // Read the curve.
    std::vector<Real> V;
    {
        std::ifstream f ( curve_file, std::ios::binary | std::ios::ate );
        if( !f ) { std::fprintf( stderr, "cannot open %s\n", curve_file.c_str() ); return 1; }
        const std::streamsize bytes = f.tellg();
        if( (bytes <= 0) || (bytes % static_cast<std::streamsize>(3 * sizeof(Real)) != 0) )
        {
            std::fprintf( stderr, "%s is not a float64 (N,3) array\n", curve_file.c_str() );
            return 1;
        }
        V.resize( static_cast<std::size_t>(bytes) / sizeof(Real) );
        f.seekg( 0 );
        f.read( reinterpret_cast<char *>( V.data() ), bytes );
    }
    const Int n = static_cast<Int>( V.size() / 3 );

    // Closed polygon: edge i = (i, i+1 mod n).
    std::vector<Int> S ( 2 * static_cast<std::size_t>(n) );
    for( Int i = 0; i < n; ++i )
    {
        S[2 * i + 0] = i;
        S[2 * i + 1] = (i + 1 == n) ? 0 : i + 1;
    }

    const Int  dom_dim = 1;
    const Int  amb_dim = 3;
    const Real q = 2;
    const Real p = 4;

    // Factories restricted to curves in R^3 (as the examples restrict to surfaces in R^3).
    Repulsor::SimplicialMesh_Factory<Mesh_T,1,1,3,3>              mesh_factory;
    Repulsor::TangentPointEnergy0_Factory<Mesh_T,1,1,3,3>         TPE_factory;
    Repulsor::TangentPointMetric0_Factory<Mesh_T,1,1,3,3>         TPM_factory;
    Repulsor::TangentPointEnergy_AllPairs_Factory<Mesh_T,1,1,3,3> TPE_AP_factory;

    std::unique_ptr<Energy_T> tpe_ptr = TPE_factory.Make( dom_dim, amb_dim, q, p );
    std::unique_ptr<Metric_T> tpm_ptr = TPM_factory.Make( dom_dim, amb_dim, q, p );
    const auto & tpe = *tpe_ptr;
    const auto & tpm = *tpm_ptr;

    // A new mesh with its cluster tree and block cluster tree built.
    auto make_mesh = [&]()
    {
        std::unique_ptr<Mesh_T> M_ptr = mesh_factory.Make(
            V.data(), n, amb_dim, false,
            S.data(), n, dom_dim + 1, false,
            thread_count
        );
        auto & M = *M_ptr;
        M.cluster_tree_settings.split_threshold                      = 2;
        M.cluster_tree_settings.thread_count                         = thread_count;
        M.block_cluster_tree_settings.far_field_separation_parameter = theta;
        (void)M.GetBlockClusterTree(); // builds the cluster tree too
        return M_ptr;
    };

    // What every mode starts with: a new mesh, then the energy and its differential
    // (Differential first: it caches the energy it computes along; Value reads it), timed from t0.
    struct Start
    {
        std::unique_ptr<Mesh_T>   M_ptr;
        Mesh_T::CotangentVector_T diff;
        Real                      en     = 0;
        double                    t_mesh = 0;
        double                    t_eg   = 0;
    };
    auto start = [&]( const Clock::time_point t0 )
    {
        Start s;
        s.M_ptr  = make_mesh();
        s.t_mesh = seconds_since( t0 );
        s.diff   = tpe.Differential( *s.M_ptr );
        s.en     = tpe.Value( *s.M_ptr );
        s.t_eg   = seconds_since( t0 );
        return s;
    };

    const std::size_t len = static_cast<std::size_t>(n) * amb_dim;

    char head[256];
    std::snprintf( head, sizeof(head), "edges=%d threads=%d", n, thread_count );

    std::printf( "repulsor info q=%g p=%g theta=%g split_threshold=2 energy=%s\n",
        q, p, theta, tpe.ClassName().c_str() );

    if( mode == "eg" )
    {
        const Start st = start( Clock::now() );

        std::printf( "repulsor info eg mesh_seconds=%.6f energy_differential_seconds=%.6f\n",
            st.t_mesh, st.t_eg - st.t_mesh );
        std::printf( "repulsor eg %s seconds=%.6f energy=%.12e diff_norm=%.12e\n",
            head, st.t_eg, st.en, norm2( st.diff.data(), len ) );
        // --repeat K: K - 1 more new meshes and their E+g in the same process (the allocator
        // and caches warm, as in a flow that evaluates again and again)
        for( int r = 1; r < repeat; ++r )
        {
            const Start again = start( Clock::now() );
            std::printf( "repulsor info eg_again mesh_seconds=%.6f energy_differential_seconds=%.6f\n",
                again.t_mesh, again.t_eg - again.t_mesh );
        }
    }
    else if( mode == "iter" )
    {
        const Int  max_iter           = 100;
        const Real relative_tolerance = 0.00001;

        const auto t0 = Clock::now();
        Start st = start( t0 );
        auto & M = *st.M_ptr;
        const auto & diff = st.diff;
        const Real en = st.en;
        const double t_mesh = st.t_mesh;
        const double t_eg = st.t_eg;

        Mesh_T::TangentVector_T gradient ( M.VertexCount(), M.AmbDim() );
        tpm.Solve( M,
            Real(1), diff.data(),     M.AmbDim(),
            Real(0), gradient.data(), M.AmbDim(),
            M.AmbDim(), max_iter, relative_tolerance
        );
        const double t_solve = seconds_since( t0 );

        Mesh_T::TangentVector_T downward_gradient = gradient;
        downward_gradient *= -1.;

        const Real t = M.MaximumSafeStepSize( downward_gradient.data(), 1. );
        const double t_step = seconds_since( t0 );

        Mesh_T::TangentVector_T X = downward_gradient;
        X *= t;
        X += M.VertexCoordinates();
        M.SemiStaticUpdate( X.data() );
        const double t_move = seconds_since( t0 );

        const Real en_new = tpe.Value( M );
        const double s = seconds_since( t0 );

        const auto res = tpm.Solver_RelativeResiduals();
        std::string res_str;
        for( Int k = 0; k < static_cast<Int>(res.Size()); ++k )
        {
            char b[32];
            std::snprintf( b, sizeof(b), "%s%.3e", k ? "," : "", static_cast<double>(res[k]) );
            res_str += b;
        }
        std::printf( "repulsor info iter mesh_seconds=%.6f eg_seconds=%.6f solve_seconds=%.6f "
            "step_seconds=%.6f move_seconds=%.6f energy_new_seconds=%.6f gmres_iterations=%d "
            "gmres_relative_residuals=%s\n",
            t_mesh, t_eg - t_mesh, t_solve - t_eg, t_step - t_solve, t_move - t_step,
            s - t_move, static_cast<int>( tpm.Solver_IterationCount() ), res_str.c_str() );
        std::printf( "repulsor iter %s seconds=%.6f energy=%.12e energy_new=%.12e step=%.6e\n",
            head, s, en, en_new, t );
    }
    else // error
    {
        std::unique_ptr<Energy_T> ap_ptr = TPE_AP_factory.Make( dom_dim, amb_dim, q, p );
        const auto & tpe_ap = *ap_ptr;

        const Start st = start( Clock::now() );
        auto & M = *st.M_ptr;
        const auto & diff_tree = st.diff;
        const Real en_tree = st.en;
        const double s_tree = st.t_eg;

        const auto t1 = Clock::now();
        Mesh_T::CotangentVector_T diff_exact = tpe_ap.Differential( M );
        const Real en_exact = tpe_ap.Value( M );
        const double s_exact = seconds_since( t1 );

        const double e_rel = std::fabs( en_tree - en_exact ) / std::fabs( en_exact );
        const double d_rel = diff_norm2( diff_tree.data(), diff_exact.data(), len )
                           / norm2( diff_exact.data(), len );

        std::printf( "repulsor info error exact=%s exact_seconds=%.6f diff_norm_tree=%.12e "
            "diff_norm_exact=%.12e\n", tpe_ap.ClassName().c_str(), s_exact,
            norm2( diff_tree.data(), len ), norm2( diff_exact.data(), len ) );
        std::printf( "repulsor error %s energy_tree=%.12e energy_exact=%.12e "
            "energy_rel_error=%.3e diff_rel_error=%.3e tree_seconds=%.6f\n",
            head, en_tree, en_exact, e_rel, d_rel, s_tree );
    }

    std::printf( "repulsor memory mode=%s %s peak_rss_mb=%.1f\n",
        mode.c_str(), head, peak_rss_mb() );
    std::fflush( stdout );
    return 0;
}
